"""The harness: experiments built on the cycle, their statistics, files and reports.

* `jobs`: a job is a fixed chunk of trials of one scenario with one method; sweeps and
  in-process comparisons as lists of jobs;
* `statistics`: every mean, spread, paired difference, interval and number format;
* `reproduce`: the paper's Section 7 (Figs. 5-9), the first guess and the sensitivity study;
* `robustness`, `trackers`, `flight`, `sensing`, `separation`, `bandwidth`, `realistic`:
  the faults, trackers, real-flight, sensing, one-altitude, radio-load and
  realistic-mission experiments, each an implementation of `protocol.Experiment`;
* `protocol`: what an experiment command implements (its profile, plan, summary,
  figures and report);
* `store`: the output folder that never loses work, and the local and Dask engines;
* `report`, `figures`: report.md and the paper's figures from a summary;
* `bench`: speed measurements beside their references;
* `learned`: learned teams against the paper's planner (training and paired evaluation).

Nothing in the model, the cycle or its forms imports this package.
"""

import importlib
import warnings

_MOVED = {
    "reproduce": (
        "METHOD_NAMES", "PAPER_FIG5", "FIRST_GUESS", "SENSITIVITY", "NEAR_CENTRALIZED",
        "ABOVE_GREEDY", "Profile", "reproduce_plan", "resized", "summarize_reproduction",
        "conclusions",
    ),
    "statistics": ("describe", "paired", "PAIRED_METRICS", "against_first", "summarize"),
    "jobs": (
        "Job", "LABEL_CHARS", "run_job", "UNDEFINED_ALLOWED", "check_finite", "label_of",
        "difference", "trial_jobs", "label_for", "sweep_values", "sweep_axes", "sweep_cells",
        "cell_text", "sweep_plan", "unique", "collect", "summarize_sweep", "trials", "compare",
    ),
}  # fmt: skip
"""Where each name of the former module ``uavtrack.experiments`` lives now."""


def __getattr__(name: str):
    for module, names in _MOVED.items():
        if name in names:
            warnings.warn(
                f"uavtrack.experiments.{name} moved to uavtrack.experiments.{module}.{name}; "
                "the old path goes in the next release",
                DeprecationWarning,
                stacklevel=2,
            )
            return getattr(importlib.import_module(f".{module}", __name__), name)
    raise AttributeError(f"module 'uavtrack.experiments' has no attribute {name!r}")
