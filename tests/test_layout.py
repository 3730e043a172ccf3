"""The layers of the package and the walls between them (DESIGN.md, "Layout"), checked
over every import of every module, those inside functions included.

    base      errors, _files, _progress, _process      imports nothing else
    config    config/                                   base only
    model     the stage modules, simulation, timing, testing, methods/, robust/, flight/
    forms     agents/, env/, io/, viz/                  never the harness or the command line
    harness   experiments/                              never the command line
    top       cli/, _console, the package's __init__    anything
"""

from __future__ import annotations

import ast
import importlib
import sys
import warnings
from pathlib import Path

import pytest

import uavtrack

PACKAGE = Path(uavtrack.__file__).parent

LAYERS = {
    "base": {"errors", "_files", "_progress", "_process", "numerics", "limits"},
    "config": {"config"},
    "model": {
        "world", "network", "faults", "radio", "sensing", "estimation", "fusion", "planning",
        "assignment", "metrics", "records", "simulation", "timing", "testing", "methods",
        "robust", "flight",
        "tracks", "airspace",
    },
    "forms": {"agents", "env", "io", "viz"},
    "harness": {"experiments"},
    "top": {"cli", "_console", ""},
}  # fmt: skip
"""Each top-level module or package of uavtrack by layer ("" is the package itself)."""

MAY_IMPORT = {
    "base": {"base"},
    "config": {"base", "config"},
    "model": {"base", "config", "model"},
    "forms": {"base", "config", "model", "forms"},
    "harness": {"base", "config", "model", "forms", "harness"},
    "top": set(LAYERS),
}
"""The walls: what each layer may import."""

MOST_TOP_LEVEL = 21
"""Modules at the top of the package besides packages (``__init__`` counted)."""


def modules(root: Path) -> dict[str, Path]:
    """Every module under `root` (a package folder) by dotted name."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imports(root: Path, typing: bool = True) -> list[tuple[str, str, int]]:
    """(importer, imported, line) for every import of a module of the package in `root`,
    anywhere in a module (at its top, in a function, and, if `typing`, under
    ``if TYPE_CHECKING``); ``from . import x`` names the module x where there is one."""
    found = modules(root)
    package = root.name
    out = []
    for name, path in found.items():
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        hints = {
            id(inner)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and ast.unparse(node.test).endswith("TYPE_CHECKING")
            for inner in ast.walk(node)
        }
        for node in ast.walk(tree):
            if not typing and id(node) in hints:
                continue
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    up = here.split(".")[: len(here.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                targets = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in found else base for a in node.names
                ]
            else:
                continue
            for target in targets:
                if target == package and all(a.name == "__version__" for a in node.names):
                    continue  # the version, a constant of the package, is for every layer
                if target == package or target.startswith(package + "."):
                    while target not in found:  # a name inside a module: the module
                        target = target.rpartition(".")[0]
                    if target != name:
                        out.append((name, target, node.lineno))
    return out


def layer(module: str) -> str:
    top = module.split(".")[1] if "." in module else ""
    for name, members in LAYERS.items():
        if top in members:
            return name
    raise AssertionError(f"{module} is in no layer: add it to LAYERS (and to DESIGN.md)")


def crossings(root: Path) -> list[str]:
    """Every import across a wall, as a line naming it."""
    return sorted(
        f"{a} (line {line}) imports {b}: the {layer(a)} may not import the {layer(b)}"
        for a, b, line in imports(root)
        if layer(b) not in MAY_IMPORT[layer(a)]
    )


def cycles(root: Path, typing: bool = False) -> list[list[str]]:
    """The import cycles among the package's modules (strongly connected components of
    more than one module), counting imports inside functions, and with `typing` those
    only a type checker reads (``if TYPE_CHECKING``)."""
    graph: dict[str, set[str]] = {name: set() for name in modules(root)}
    for a, b, _ in imports(root, typing=typing):
        graph[a].add(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_crosses_a_wall():
    assert crossings(PACKAGE) == []


def test_no_import_cycle_counting_imports_inside_functions():
    assert cycles(PACKAGE) == []


def test_no_import_cycle_even_through_typing():
    """The cycle's records sit below the metrics and the driver (`records`): nothing
    names the driver to name a type."""
    assert cycles(PACKAGE, typing=True) == []


MODEL_ORDER = (
    {"world", "network", "faults", "radio", "sensing", "estimation", "planning", "assignment",
     "timing", "flight", "robust", "airspace"},
    {"fusion"},
    {"tracks"},
    {"methods"},
    {"records"},
    {"metrics", "tracks.scoring"},
    {"simulation", "testing"},
)  # fmt: skip
"""The model's inner order, low to high: the stages, fusion, tracks, methods, the cycle's
records, the evaluation (metrics and the track scoring), the driver. A module imports
only its own rank and those below (typing imports included): a stage that imports a
method, or the metrics the driver, fails it."""


def rank(module: str) -> int:
    parts = module.split(".")[1:]
    for name in (".".join(parts[:2]), parts[0]):
        for k, members in enumerate(MODEL_ORDER):
            if name in members:
                return k
    raise AssertionError(f"{module} is in no rank of MODEL_ORDER: add it")


def order_breaches(root: Path) -> list[str]:
    """Every import of the model that reaches above its own rank, as a line naming it."""
    return sorted(
        f"{a} (line {line}) imports {b}, above it in the model's order"
        for a, b, line in imports(root)
        if layer(a) == layer(b) == "model" and rank(b) > rank(a)
    )


def test_the_model_keeps_its_inner_order():
    assert order_breaches(PACKAGE) == []


def test_every_module_is_in_a_layer_and_the_top_is_small():
    for name in modules(PACKAGE):
        layer(name)
    top = sorted(p.stem for p in PACKAGE.glob("*.py"))
    assert len(top) <= MOST_TOP_LEVEL, top


@pytest.fixture
def package(tmp_path):
    """A copy of uavtrack's sources to break."""
    root = tmp_path / "uavtrack"
    for path in modules(PACKAGE).values():
        target = root / path.relative_to(PACKAGE)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(path.read_text(encoding="utf-8"), encoding="utf-8")
    return root


def test_an_import_added_across_a_wall_is_caught_even_inside_a_function(package):
    world = package / "world.py"
    world.write_text(
        world.read_text() + "\n\ndef later():\n    from .experiments.jobs import run_job\n",
    )
    assert crossings(package) == [
        f"uavtrack.world (line {len(world.read_text().splitlines())}) imports "
        "uavtrack.experiments.jobs: the model may not import the harness"
    ]
    env = package / "env" / "vector.py"
    env.write_text(env.read_text() + "\nimport uavtrack.cli  # noqa\n")
    assert any("uavtrack.env.vector" in line and "the top" in line for line in crossings(package))


def test_an_import_cycle_through_a_function_is_caught(package):
    network = package / "network.py"
    network.write_text(network.read_text() + "\n\ndef later():\n    from . import radio\n")
    assert ["uavtrack.faults", "uavtrack.network", "uavtrack.radio"] in cycles(package) or any(
        {"uavtrack.network", "uavtrack.radio"} <= set(c) for c in cycles(package)
    )


def test_a_stage_that_names_a_method_or_the_driver_for_a_type_is_caught(package):
    """A typing import counts: the estimation stage naming the methods' records breaks the
    order, and the metrics naming the driver's module for a type makes a cycle."""
    estimation = package / "estimation.py"
    estimation.write_text(
        estimation.read_text()
        + "\nfrom typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        + "    from .methods.base import Held  # noqa\n"
    )
    assert any(
        line.startswith("uavtrack.estimation") and "uavtrack.methods.base" in line
        for line in order_breaches(package)
    )
    metrics = package / "metrics.py"
    metrics.write_text(
        metrics.read_text() + "\nif TYPE_CHECKING:\n    from .simulation import State  # noqa\n"
    )
    assert any({"uavtrack.metrics", "uavtrack.simulation"} <= set(c) for c in cycles(package, True))
    assert not any("uavtrack.metrics" in c for c in cycles(package))  # not run: no cycle


def test_config_imports_nothing_but_errors():
    used = {b for a, b, _ in imports(PACKAGE) if a.startswith("uavtrack.config")}
    assert {b for b in used if not b.startswith("uavtrack.config")} == {"uavtrack.errors"}


# ------------------------------------------------------------------ the old paths


@pytest.mark.parametrize(
    ("old", "name", "new"),
    [
        ("uavtrack.runner", "Store", "uavtrack.experiments.store"),
        ("uavtrack.plots", "fig5", "uavtrack.experiments.figures"),
        ("uavtrack.plots", "animate", "uavtrack.viz.scene"),
        ("uavtrack.report", "pm", "uavtrack.experiments.statistics"),
        ("uavtrack.robustness", "ci95", "uavtrack.experiments.statistics"),
        ("uavtrack.trackers", "TRACKERS", "uavtrack.experiments.trackers"),
        ("uavtrack.files", "write_json", "uavtrack._files"),
        ("uavtrack.threads", "pin", "uavtrack._process"),
        ("uavtrack.lifeline", "die_with", "uavtrack._process"),
        ("uavtrack.equivalence", "assert_same_trace", "uavtrack.testing"),
        ("uavtrack.gate", "seen", "uavtrack.robust.gate"),
        ("uavtrack.registry", "names", "uavtrack.methods.registry"),
        ("uavtrack.viewer", "save", "uavtrack.viz.rerun"),
        ("uavtrack.flight.mavlink", "LocalFrame", "uavtrack.io.mavlink"),
        ("uavtrack.flight.experiment", "plan", "uavtrack.experiments.flight"),
    ],
)
def test_an_old_import_path_warns_and_gives_the_same_object(old, name, new):
    pytest.importorskip(new.replace("uavtrack.viz.rerun", "rerun"))
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=f"{old} moved to .*{new}"):
        module = importlib.import_module(old)
    assert getattr(module, name) is getattr(importlib.import_module(new), name)


def test_every_old_path_is_gone_and_every_new_one_is_there():
    found = modules(PACKAGE)
    for old, new in uavtrack._MOVED.items():
        assert old not in found, f"{old} is a module again: take it out of the old paths"
        assert set(new.split()) <= set(found), new


def test_the_old_names_of_experiments_warn_and_lead_to_their_modules():
    from uavtrack.experiments import jobs, reproduce, statistics

    for name, home in (("describe", statistics), ("Profile", reproduce), ("Job", jobs)):
        with pytest.warns(DeprecationWarning, match=f"experiments.{home.__name__.split('.')[-1]}"):
            assert getattr(uavtrack.experiments, name) is getattr(home, name)


def test_the_new_paths_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in ("experiments.store", "experiments.figures", "viz.scene", "testing"):
            importlib.import_module(f"uavtrack.{name}")


# ------------------------------------------------------------------ JSBSim only in flight


def test_a_jsbsim_scenario_is_built_and_read_without_jsbsim(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "jsbsim", None)  # import jsbsim now fails
    scenario = uavtrack.Scenario(uav={"dynamics": "jsbsim", "aircraft": "trackwing"})
    path = tmp_path / "flown.toml"
    path.write_text(scenario.to_toml())
    assert uavtrack.Scenario.from_toml(path) == scenario
    from uavtrack import flight

    with pytest.raises(uavtrack.ScenarioError, match="needs JSBSim"):
        flight.check(scenario)
    flight.check(uavtrack.Scenario())  # the unicycle needs nothing


def test_every_subpackage_names_each_of_its_modules_and_the_cli_each_command():
    """A package's docstring is its map: it names every module in it (so a new module
    cannot go unmentioned), and the command line's names every command it has."""
    import ast
    import re
    from pathlib import Path

    from uavtrack import cli

    root = Path(uavtrack.__file__).parent
    for init in sorted(root.glob("*/__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        modules = [p.stem for p in init.parent.glob("*.py") if not p.stem.startswith("_")]
        missing = [m for m in modules if not re.search(rf"\b{m}\b", doc)]
        assert not missing, (init.parent.name, missing)
    commands = {
        c.name or c.callback.__name__.replace("_", "-") for c in cli.app.registered_commands
    }
    listed = set(re.findall(r"\w+", cli.__doc__.split("``")[1])) - {"uavtrack"}
    assert listed == commands, listed ^ commands
