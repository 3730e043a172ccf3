"""The documentation: a short README whose links resolve, a site that builds strictly,
tutorials whose code runs, and pages that a browser draws."""

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent
DOCS = ROOT / "docs"
TUTORIALS = ["getting-started.md", "tutorials/one-scenario.md", "tutorials/compare.md",
             "tutorials/sweep.md"]  # fmt: skip


def test_the_readme_is_short_and_starts_with_the_two_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 200
    assert lines[3].startswith("pip install . && uavtrack reproduce")
    assert lines[4].startswith('pip install -e ".[test]" && pytest')


def test_the_scenario_fields_page_is_current():
    hooks = docs_module("hooks")
    page = (DOCS / "reference" / "scenario.md").read_text()
    table = page.split(hooks.BEGIN)[1].split(hooks.END)[0].strip()
    assert table == hooks.scenario_fields(), "run: python docs/hooks.py"


def test_every_link_of_the_readme_resolves():
    text = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert len(links) > 20
    missing = [link for link in links if not link.startswith("http") and not (ROOT / link).exists()]
    assert not missing


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    return out


@pytest.mark.integration
def test_the_site_builds_strictly_with_its_generated_pages(site):
    fields = (site / "reference" / "scenario" / "index.html").read_text()
    import uavtrack

    for name, _, _ in uavtrack.Scenario().describe():  # every field, from the models
        assert f"<code>{name}</code>" in fields, name
    cli = (site / "reference" / "cli" / "index.html").read_text()
    for command in ("run", "compare", "sweep", "reproduce", "export", "swarm"):
        assert f"Usage: uavtrack {command}" in cli
    api = (site / "reference" / "api" / "index.html").read_text()
    assert all(f'href="{page}/"' in api for page in API_PAGES)
    assert (site / "search" / "search_index.json").stat().st_size > 10_000


API_PAGES = ("model", "simulation", "methods", "scenario", "forms", "harness")
STAGES = ("world", "network", "faults", "radio", "sensing", "estimation", "fusion", "planning",
          "assignment", "metrics", "gate", "plausibility", "flight")  # fmt: skip


def api_blocks(page: str):
    """(target, options text) of every ``:::`` block of an API page."""
    source = (DOCS / "reference" / "api" / f"{page}.md").read_text()
    return re.findall(r"^::: (\S+)\n((?:    .*\n)*)", source, flags=re.M)


@pytest.mark.integration  # the site is built by mkdocs, a process
@pytest.mark.parametrize("page", API_PAGES)
def test_every_object_an_api_page_names_renders_with_its_docstring(site, page):
    # mkdocstrings renders nothing, silently, for a member a `members:` list misspells
    import html as html_text

    html = (site / "reference" / "api" / page / "index.html").read_text()
    parts = re.split(r'<h\d id="([^"]+)" class="doc doc-heading">', html)
    rendered = {
        parts[i]: re.sub(r"\s+", " ", html_text.unescape(re.sub(r"<[^>]+>", " ", parts[i + 1])))
        for i in range(1, len(parts), 2)
    }  # id -> its heading and docstring as text
    named = 0
    for target, options in api_blocks(page):
        wanted = [] if "show_root_heading: false" in options else [target]
        members = re.search(r"members: \[(.+)\]", options)
        if members:
            wanted += [f"{target}.{m.strip()}" for m in members.group(1).split(",")]
        for name in wanted:
            assert name in rendered, f"{page}: {name} is not rendered"
            heading, _, text = rendered[name].partition("¶")
            assert name.rsplit(".", 1)[1] in heading and len(text.split()) >= 4, name
            named += 1
    assert named >= 20


def docstrings(module: str, names: list[str]) -> str:
    """The docstrings of `names` (functions, classes, Class.method, sub.Name) of a
    uavtrack module and of the modules they are in, read from the source."""
    import ast

    def source(dotted: str):
        base = ROOT / "src" / Path(*dotted.split("."))
        path = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
        return ast.parse(path.read_text()) if path.exists() else None

    texts = [ast.get_docstring(source(module)) or ""]
    for name in names:
        *sub, obj = name.split(".")
        path = module
        while sub and source(f"{path}.{sub[0]}") is not None:  # sub.Name: a submodule's
            path = f"{path}.{sub.pop(0)}"
        tree = source(path)
        texts.append(ast.get_docstring(tree) or "")
        for node in [n for n in ast.walk(tree) if hasattr(n, "name")]:
            if node.name == obj and (not sub or node in ast.walk(_named(tree, sub[0]))):
                texts.append(ast.get_docstring(node) or "")
    return "\n".join(texts)


def _named(tree, name: str):
    return next(n for n in tree.body if getattr(n, "name", None) == name)


def equations(text: str) -> set[int]:
    """The equation numbers a text cites: eq. (3), eqs. (2)-(4), eqs. 3 and 10-12, ..."""
    found = set()
    for run in re.findall(r"eqs?\.\s*((?:\(?\d+\)?(?:\s*(?:-|,|and)\s*)?)+)", text):
        for token in re.sub(r"\band\b", ",", re.sub(r"[()]", "", run)).split(","):
            ends = [int(x) for x in re.findall(r"\d+", token)]
            if len(ends) == 2 and "-" in token:
                found |= set(range(ends[0], ends[1] + 1))
            else:
                found |= set(ends)
    return found


def test_equations_cited_in_table_are_those_their_objects_docstrings_cite():
    # the model page's tables (function -> equation) are written by hand: each equation
    # they give must be one the docstrings of the named objects (or their module) cite
    page = (DOCS / "reference" / "api" / "model.md").read_text()
    sections = re.findall(r"^## `(uavtrack\.[\w.]+)`: .*?\{#(\w+)\}\n(.*?)(?=^## |\Z)", page,
                          flags=re.M | re.S)  # fmt: skip
    assert [anchor for _, anchor, _ in sections] == list(STAGES)  # Fig. 3's order
    rows = 0
    for module, _, body in sections:
        for first, rest in re.findall(r"^\| ([^|]*`[^|]*) \| (.*) \|$", body, flags=re.M):
            cited = equations(rest)
            names = re.findall(r"`([\w.]+)`", first)
            assert cited <= equations(docstrings(module, names)), (module, first, cited)
            rows += bool(cited)
    assert rows >= 20


@pytest.mark.slow  # a whole build (25 s); the default suite builds the site strictly
@pytest.mark.integration
def test_a_broken_link_fails_the_build(tmp_path):
    pytest.importorskip("mkdocs")
    import shutil

    copy = tmp_path / "project"
    shutil.copytree(DOCS, copy / "docs")
    shutil.copy(ROOT / "mkdocs.yml", copy)
    shutil.copytree(ROOT / "src", copy / "src")
    page = copy / "docs" / "tutorials" / "sweep.md"
    page.write_text(page.read_text() + "\n[gone](no-such-page.md)\n")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "s")],
        cwd=copy, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode != 0 and "no-such-page.md" in done.stdout + done.stderr


def python_blocks(page):
    return re.findall(r"```python\n(.*?)```", (DOCS / page).read_text(), flags=re.S)


@pytest.mark.parametrize("page", TUTORIALS)
def test_the_tutorials_code_runs(page, tmp_path, monkeypatch):
    blocks = python_blocks(page)
    assert blocks, page
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, f"{page}", "exec"), {"__name__": "__tutorial__"})


@pytest.mark.parametrize("page", TUTORIALS)
def test_the_tutorials_import_only_what_pip_install_brings(page):
    # the tutorials follow `pip install .`: no test tool, no extra
    import ast
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    installed = {re.split(r"[<>=\[ ;]", d)[0].lower() for d in project["dependencies"]}
    allowed = installed | set(sys.stdlib_module_names) | {"uavtrack"}
    for block in python_blocks(page):
        for node in ast.walk(ast.parse(block)):
            names = (
                [a.name for a in node.names] if isinstance(node, ast.Import)
                else [node.module] if isinstance(node, ast.ImportFrom) and node.module
                else []
            )  # fmt: skip
            for name in names:
                assert name.split(".")[0] in allowed, f"{page} imports {name}"


@pytest.mark.parametrize(
    "page", ["api.md", "api/simulation.md", "api/methods.md", "api/scenario.md", "api/harness.md"]
)
def test_the_api_pages_code_runs(page, tmp_path, monkeypatch):
    from uavtrack.methods import registry

    monkeypatch.setattr(registry, "_REGISTERED", dict(registry._REGISTERED))  # `register`s
    monkeypatch.chdir(tmp_path)  # files a page writes
    blocks = python_blocks(f"reference/{page}")
    assert blocks, page
    for block in blocks:
        exec(compile(block, page, "exec"), {"__name__": "__api_page__"})


def docs_module(name: str):
    """A module of the docs folder (hooks, screenshot)."""
    sys.path.insert(0, str(DOCS))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(DOCS))


@pytest.mark.integration
def test_a_browser_draws_the_main_pages(site, tmp_path):
    screenshot = docs_module("screenshot")
    if screenshot.chromium() is None:
        pytest.skip("no Chromium here (python docs/screenshot.py documents the check)")
    from PIL import Image

    shots = screenshot.shoot(site, tmp_path, pages=("index.html", "reference/api/index.html"))
    for shot in shots:
        image = Image.open(shot).convert("RGB")
        assert image.size == (1280, 1600)
        colours = image.getcolors(1 << 20)
        assert colours is not None and len(colours) > 50, shot  # text, figure, navigation


@pytest.mark.integration
@pytest.mark.parametrize(
    "page",
    ["getting-started/index.html", "tutorials/sweep/index.html", "reference/cli/index.html",
     "reference/scenario/index.html", "reference/api/index.html",
     "reference/api/model/index.html", "reference/api/simulation/index.html"],
)  # fmt: skip
def test_no_command_runs_past_its_block_and_no_field_name_breaks(site, page):
    # at 1280 pixels, as the browser lays the page out: the comment at the end of a long
    # command stays in view, and a dotted name in a table stays whole
    assert (site / page).is_file(), page  # the browser finds nothing wrong on a missing page
    screenshot = docs_module("screenshot")
    if screenshot.chromium() is None:
        pytest.skip("no Chromium here (python docs/screenshot.py documents the check)")
    assert screenshot.hidden(site, page) == {"cut": [], "broken": []}


def printed_blocks() -> list[tuple[str, str, str]]:
    """(page, code, output) of every python block a page follows with what it prints (a
    short paragraph, then a text block)."""
    found = []
    for page in sorted(DOCS.rglob("*.md")):
        text = page.read_text()
        pattern = r"```python\n(.*?)```\n\n([^`]{0,200}?)```text\n(.*?)```"
        for m in re.finditer(pattern, text, flags=re.S):
            if "prints" in m.group(2):
                found.append((str(page.relative_to(DOCS)), m.group(1), m.group(3)))
    return found


def test_what_a_page_says_its_code_prints_is_what_it_prints(tmp_path, monkeypatch):
    import contextlib
    import io

    blocks = printed_blocks()
    assert blocks  # docs/concepts.md's cycle and trace fields at least
    monkeypatch.chdir(tmp_path)
    for page, code, output in blocks:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(code, page, "exec"), {"__name__": "__page__"})
        assert out.getvalue() == output, f"{page}: its printed output is not what it prints"


MARKS_PLUGIN = """
import json, os

def pytest_collection_modifyitems(session, config, items):
    rows = [sorted({m.name for m in item.iter_markers()}) for item in items]
    with open(os.environ["UAVTRACK_MARKS"], "w") as f:
        json.dump(rows, f)
"""
"""A pytest plugin that writes every collected test's markers, before any selection."""


def collected(tmp_path) -> dict[str, int]:
    """How many tests each of the suites collects (`pytest -m MARKS`), from one
    collection in a process of its own: every test's markers, counted per suite."""
    import json
    import os
    import subprocess

    (tmp_path / "uavtrack_marks.py").write_text(MARKS_PLUGIN)
    out = tmp_path / "marks.json"
    env = dict(os.environ, UAVTRACK_MARKS=str(out))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), env.get("PYTHONPATH")]))
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
         "-p", "uavtrack_marks", str(ROOT / "tests")],
        capture_output=True, text=True, cwd=ROOT, timeout=600, env=env,
    )  # fmt: skip
    assert out.exists(), done.stdout[-2000:] + done.stderr[-2000:]
    marks = [set(row) for row in json.loads(out.read_text())]
    slow = [m for m in marks if "slow" in m]
    rest = [m for m in marks if "slow" not in m]
    return {
        "fast": sum("integration" not in m for m in rest),
        "default": len(rest),
        "slow": len(slow),
        "integration": sum("integration" in m for m in rest),
    }


@pytest.mark.integration  # collects the suite in a process of its own
def test_the_test_counts_the_pages_give_are_the_suites(tmp_path):
    """The README's and docs/tests.md's counts are what pytest collects: a test added
    without them fails here, so they cannot drift."""
    counts = collected(tmp_path)
    readme, page = (ROOT / "README.md").read_text(), (DOCS / "tests.md").read_text()
    expected = {
        "README default": (readme, f"({counts['default']:,} tests,"),
        "README fast": (readme, f"({counts['fast']:,} tests,"),
        "tests.md fast": (page, f"in one process: {counts['fast']:,} tests"),
        "tests.md default": (page, f"everything but the slow tests: {counts['default']:,} tests"),
        "tests.md slow": (page, f"namespaces: {counts['slow']} tests"),
        "tests.md integration": (page, f"the {counts['integration']:,} tests that start"),
    }
    wrong = [where for where, (text, phrase) in expected.items() if phrase not in text]
    assert not wrong, (wrong, counts)
