"""The documentation: a short README whose links resolve, a site that builds strictly,
tutorials whose code runs, and pages that a browser draws."""

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
    sys.path.insert(0, str(DOCS))
    try:
        import hooks
    finally:
        sys.path.remove(str(DOCS))
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


def test_a_browser_draws_the_main_pages(site, tmp_path):
    sys.path.insert(0, str(DOCS))
    try:
        import screenshot
    finally:
        sys.path.remove(str(DOCS))
    if screenshot.chromium() is None:
        pytest.skip("no Chromium here (python docs/screenshot.py documents the check)")
    from PIL import Image

    shots = screenshot.shoot(site, tmp_path, pages=("index.html", "reference/api/index.html"))
    for shot in shots:
        image = Image.open(shot).convert("RGB")
        assert image.size == (1280, 1600)
        colours = image.getcolors(1 << 20)
        assert colours is not None and len(colours) > 50, shot  # text, figure, navigation
