"""The two kinds of failure the command line tells apart.

* `UsageError`: the input cannot be used (a field out of range, a file that cannot be
  written, a folder in use); nothing was computed. The command line exits with 2.
* `RunError`: the input was fine but the run could not finish (a worker died, the disk
  filled up); what was finished is kept. The command line exits with 1.

An interrupted run (`Interrupted`, exit code 130) is a `RunError` whose message says
what was kept. All carry a one-line message meant for the user.
"""


class UsageError(ValueError):
    """Bad input: the message names what is wrong, in one line."""


class ScenarioError(UsageError):
    """A scenario, config file or override that cannot be used; the message is one line."""


class RunError(RuntimeError):
    """A run that could not finish; finished work is kept. The message is one line."""


class Interrupted(RunError):
    """The user interrupted a run (Ctrl-C); the message says what was kept."""


EXTRAS = {
    "agents": "eclipse-zenoh",
    "bench": "filterpy pyinstrument",
    "dask": '"dask[distributed]"',
    "docs": "mkdocs mkdocs-material mkdocstrings[python]",
    "env": "pettingzoo gymnasium",
    "flight": "jsbsim pymavlink",
    "io": "xarray pandas pyarrow h5netcdf h5py rosbags",
    "learn": "torch stable-baselines3 supersuit torchrl benchmarl torch-geometric",
    "viz": "rerun-sdk pyarrow",
}
"""The packages of each optional extra (as pyproject.toml lists them)."""


def install_hint(extra: str) -> str:
    """How to install an extra: from a checkout of uavtrack, or its packages alone."""
    return f'pip install ".[{extra}]" in a uavtrack checkout, or pip install {EXTRAS[extra]}'
