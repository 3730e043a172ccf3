"""MkDocs hooks: pages generated from the code at build time, so that they cannot drift.

* the table between ``<!-- scenario-fields: begin -->`` and ``<!-- scenario-fields: end -->``
  in reference/scenario.md: every scenario field with its default, unit, range and source
  (`uavtrack.Scenario.describe`), kept in the file so that it reads in the repository too
  (``python docs/hooks.py`` writes it; a test checks that it is current);
* ``<!-- cli-help -->``: the help of every command (`uavtrack <command> --help`);
* ``<!-- metrics -->``: every metric with its unit and meaning (`uavtrack.metrics.METRICS`).
"""

from __future__ import annotations

import io
import json
from contextlib import redirect_stdout


def on_page_markdown(markdown: str, page, config, files) -> str:
    if "<!-- cli-help -->" in markdown:
        markdown = markdown.replace("<!-- cli-help -->", cli_help())
    if "<!-- metrics -->" in markdown:
        markdown = markdown.replace("<!-- metrics -->", metrics())
    return markdown


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def scenario_fields() -> str:
    import uavtrack

    rows = ["| field | default | unit, range and source |", "|---|---|---|"]
    for name, value, doc in uavtrack.Scenario().describe():
        shown = json.dumps(value) if not isinstance(value, str) else value
        rows.append(f"| `{name}` | `{_cell(shown)}` | {_cell(doc)} |")
    return "\n".join(rows)


def metrics() -> str:
    from uavtrack.metrics import METRICS

    rows = ["| metric | unit | meaning |", "|---|---|---|"]
    rows += [f"| `{n}` | {_cell(u) or '-'} | {_cell(d)} |" for n, (u, d) in METRICS.items()]
    return "\n".join(rows)


def cli_help() -> str:
    import os

    from uavtrack import cli

    os.environ.setdefault("COLUMNS", "100")
    os.environ["NO_COLOR"] = "1"
    names = sorted(c.name or c.callback.__name__ for c in cli.app.registered_commands)
    out = []
    for name in names:
        buffer = io.StringIO()
        with redirect_stdout(buffer):
            try:
                cli.main([name, "--help"])
            except SystemExit:
                pass
        out += [f"### `uavtrack {name}`", "", "```text", buffer.getvalue().rstrip(), "```", ""]
    return "\n".join(out)


BEGIN, END = "<!-- scenario-fields: begin -->", "<!-- scenario-fields: end -->"


def write_scenario_fields(path) -> None:
    """Put the current table between the markers of `path` (reference/scenario.md)."""
    from pathlib import Path

    text = Path(path).read_text()
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    Path(path).write_text(f"{head}{BEGIN}\n{scenario_fields()}\n{END}{tail}")


if __name__ == "__main__":
    from pathlib import Path

    write_scenario_fields(Path(__file__).parent / "reference" / "scenario.md")
