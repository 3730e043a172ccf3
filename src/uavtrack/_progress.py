"""Progress on standard error, for every command that can take a while.

`bar` returns a function to call with the amount of work just done: on a terminal it
moves a live bar (rich); elsewhere (a log file, a CI job) it prints a line every
`EVERY` seconds of work, so a long run is never silent; with ``--no-progress`` it does
nothing. Callers need no branches.
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


EVERY = 60.0
"""Seconds between two lines of progress when standard error is not a terminal."""


@contextmanager
def bar(
    total: float, label: str, unit: str, enabled: bool | None = None, completed: float = 0
) -> Iterator[Callable[[float], None]]:
    """Progress of `total` units of work named `label`: done/total, rate, elapsed, left.

    enabled: True a live bar, False nothing, None (the default) a live bar on a terminal
    and a line every `EVERY` seconds elsewhere."""
    if enabled is False or total <= 0:
        yield lambda amount=1: None
        return
    if enabled is None and not on_terminal():
        with lines(total, label, completed) as step:
            yield step
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
    # rich keeps a task's completed as a float (Task.completed); add_task says int
    task = progress.add_task(label, total=total, completed=completed, rate="")  # pyright: ignore[reportArgumentType]
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


@contextmanager
def lines(total: float, label: str, completed: float = 0) -> Iterator[Callable[[float], None]]:
    """A line on standard error every `EVERY` seconds: how much of `total` is done."""
    start = time.monotonic()
    state = {"done": completed, "said": start}

    def advance(amount: float = 1) -> None:
        state["done"] += amount
        now = time.monotonic()
        if now - state["said"] >= EVERY:
            state["said"] = now
            elapsed = now - start
            share = state["done"] / total
            left = elapsed * (1 - share) / share if share > 0 else float("nan")
            print(
                f"uavtrack: {label}: {state['done']:g} of {total:g} ({100 * share:.0f}%), "
                f"{_duration(elapsed)} elapsed, about {_duration(left)} left",
                file=sys.stderr,
                flush=True,
            )

    yield advance


def _duration(seconds: float) -> str:
    if seconds != seconds:
        return "?"
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes} min {seconds:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"
