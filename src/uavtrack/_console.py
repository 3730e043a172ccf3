"""The ``uavtrack`` console script.

``uavtrack --version`` is answered here, before the command line loads: building the
commands loads typer and the pydantic adapters it makes for every option (about 0.3 s
here), which the version does not need. Everything else goes to `uavtrack.cli.entry`.
"""

from __future__ import annotations

import sys


def main() -> None:
    if sys.argv[1:] == ["--version"]:
        from . import __version__

        print(f"uavtrack {__version__}")
        return
    from .cli import entry

    entry()
