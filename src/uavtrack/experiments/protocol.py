"""The interface of an experiment command: what `uavtrack bandwidth`, `realistic`,
`separation`, `sensing`, `robustness`, `trackers` and `flight` each implement.

An experiment is a module with a `Profile` (its size), `plan` (the jobs), `summarize`,
`figures` and `figure` (what it draws) and `report`. `uavtrack.cli.experiments.run_experiment`
runs any of them into a results folder, resumably; the options every such command takes
(``--out``, ``--trials``, ``--steps``, ``--quick``, ``--workers``) are declared once there.
A new experiment is a new module of this shape and a command of a few lines.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, Self

if TYPE_CHECKING:
    from ..config import Scenario
    from .jobs import Job

__all__ = ["Experiment", "Profile", "header"]


@dataclass(frozen=True)
class Profile:
    """The size of an experiment's run: trials per cell, steps per trial, and trials per
    job (`chunk`, the unit a resumed run skips or redoes). `quick` is the small profile
    of ``--quick``, `QUICK` its (trials, steps, chunk)."""

    trials: int = 50
    steps: int = 500
    chunk: int = 10
    QUICK: ClassVar[tuple[int, int, int]] = (2, 40, 2)

    @classmethod
    def quick(cls) -> Self:
        """The smoke-test profile."""
        trials, steps, chunk = cls.QUICK
        return cls(trials=trials, steps=steps, chunk=chunk)

    def to_dict(self) -> dict[str, Any]:
        return {"trials": self.trials, "steps": self.steps, "chunk": self.chunk}


def header(
    title: str, trials: int, per: str, scenario: Scenario, info: dict[str, Any], how: str = ""
) -> list[str]:
    """A report's first lines: its title, the command that made it, and how the run went
    (`trials` per `per`, the steps, `how`, the seed, the workers, the time, the jobs)."""
    workers = info["workers"]
    return [
        f"# {title}",
        "",
        f"Command: `{info['command']}`  ",
        f"{trials} trials per {per}, {scenario.steps} steps{how}, seed {info['seed']}; "
        f"{workers} worker{'s' if workers != 1 else ''}; {info['seconds']:.0f} s "
        f"({info['jobs_run']} jobs run, {info['jobs_skipped']} already done).",
    ]


class Experiment(Protocol):
    """An experiment command's model: each experiment module implements it."""

    @property
    def NAME(self) -> str:  # noqa: N802 (the module's constant)
        """The command, and the results folder's default name (results/NAME)."""
        ...

    @property
    def Profile(self) -> type[Profile]:  # noqa: N802 (the module's class)
        """Its size, with the defaults of a full run."""
        ...

    def plan(self, base: Scenario, profile: Any, seed: int = 0, /) -> dict[str, list[Job]]:
        """The jobs, by group, each with its scenario, method and trials."""
        ...

    def summarize(
        self,
        jobs: dict[str, list[Job]],
        results: dict[str, dict[str, Any]],
        profile: Any,
        scenario: Scenario,
        /,
    ) -> dict[str, Any]:
        """The summary.json of the jobs' results."""
        ...

    def figures(self, jobs: dict[str, list[Job]], /) -> list[str]:
        """The names of the figures `figure` draws (a folder lists them before the run)."""
        ...

    def figure(self, summary: dict[str, Any], out: Path, /) -> None:
        """Draw the figures into the folder `out`."""
        ...

    def report(self, summary: dict[str, Any], scenario: Scenario, info: dict[str, Any], /) -> str:
        """The report.md: the scenario, the results and the goals, in Markdown."""
        ...
