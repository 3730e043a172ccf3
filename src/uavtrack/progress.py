"""Progress bars on standard error (rich), for every command that can take a while.

`bar` returns a function to call with the amount of work just done; when disabled (not
a terminal, or ``--no-progress``) it returns a function that does nothing, so callers
need no branches.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


def on_terminal() -> bool:
    """Whether standard error is a terminal (where a live bar makes sense)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


@contextmanager
def bar(
    total: float, label: str, unit: str, enabled: bool = True, completed: float = 0
) -> Iterator[Callable[[float], None]]:
    """A bar for `total` units of work named `label`: done/total, rate, elapsed, left."""
    if not enabled or total <= 0:
        yield lambda amount=1: None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    progress = Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TextColumn("elapsed"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=False,
    )
    task = progress.add_task(label, total=total, completed=completed, rate="")
    start, fresh = time.perf_counter(), [0.0]

    def advance(amount: float = 1) -> None:
        fresh[0] += amount
        rate = fresh[0] / max(time.perf_counter() - start, 1e-9)
        progress.update(task, advance=amount, rate=f"{rate:,.1f} {unit}/s")

    progress.start()
    try:
        yield advance
    finally:
        progress.stop()
