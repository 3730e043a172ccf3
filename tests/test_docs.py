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
    assert "uavtrack.simulate" in api and "uavtrack.env.vector_env" in api
    assert (site / "search" / "search_index.json").stat().st_size > 10_000


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
     "reference/scenario/index.html", "reference/api/index.html"],
)  # fmt: skip
def test_no_command_runs_past_its_block_and_no_field_name_breaks(site, page):
    # at 1280 pixels, as the browser lays the page out: the comment at the end of a long
    # command stays in view, and a dotted name in a table stays whole
    screenshot = docs_module("screenshot")
    if screenshot.chromium() is None:
        pytest.skip("no Chromium here (python docs/screenshot.py documents the check)")
    assert screenshot.hidden(site, page) == {"cut": [], "broken": []}
