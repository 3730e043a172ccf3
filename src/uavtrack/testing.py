"""One check that two forms of the cycle did the same thing: the same trace for form A
and form B with the same seed (and the same fault realisation).

The batch simulator, a trial run alone, the fault-free and the general path of a
cycle, the agents and the RL environment are forms of one cycle; every equivalence
test in the project goes through `assert_same_trace`, as PettingZoo's
``parallel_seed_test`` does for environments.

Decisions and truth must agree exactly: UAV and target states, observations,
assignments, actions, who is alive, and with unknown association the tracks' labels and
status and which measurement of each scan came from which target. Estimates (mean,
covariance), bids and converted measurements are floats computed in different orders by
different forms, so they agree to `atol` (1e-9 by default). Counters (rounds, messages,
late messages) are compared when both traces hold them: a form whose messages missed
their cycle says so in `late`.
"""

from __future__ import annotations

import numpy as np

EXACT = ("targets", "uavs", "observed", "assignment", "action", "alive") + (
    "label",
    "status",
    "scan_valid",
    "scan_origin",  # with unknown association
)
CLOSE = ("mean", "cov", "bids", "scan_polar", "scan_z")
COUNTERS = ("rounds", "messages", "delivered", "late", "bytes", "node_bytes", "conflicts")


def differences(a: object, b: object, atol: float = 1e-9, counters: bool = True) -> list[str]:
    """What differs between traces a and b, in words (empty when they agree).

    A trace is any object with some of the fields named above (a `records.Trace`, or
    a part of one): a field either of them lacks is not compared.
    """
    out: list[str] = []
    names = EXACT + (COUNTERS if counters else ())
    for name in names:
        x, y = getattr(a, name, None), getattr(b, name, None)
        if x is None or y is None:
            continue
        if np.shape(x) != np.shape(y):
            out.append(f"{name}: shapes {np.shape(x)} and {np.shape(y)}")
        elif not np.array_equal(x, y, equal_nan=np.asarray(x).dtype.kind == "f"):
            where = np.argwhere(np.asarray(x) != np.asarray(y))
            out.append(f"{name}: first difference at step {where[0][0]} ({len(where)} in all)")
    for name in CLOSE:
        x, y = getattr(a, name, None), getattr(b, name, None)
        if x is None or y is None:
            continue
        if np.shape(x) != np.shape(y):
            out.append(f"{name}: shapes {np.shape(x)} and {np.shape(y)}")
            continue
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        gap = np.where(np.isnan(x) & np.isnan(y), 0.0, np.abs(x - y))  # NaN: a failed UAV
        if not (gap <= atol).all():
            step = np.argwhere(~(gap <= atol))[0][0]
            out.append(f"{name}: differs by up to {np.nanmax(gap):.3g} (from step {step})")
    return out


def assert_same_trace(a: object, b: object, atol: float = 1e-9, counters: bool = True) -> None:
    """Raise AssertionError naming every field where traces a and b differ."""
    problems = differences(a, b, atol, counters)
    if problems:
        raise AssertionError("traces differ: " + "; ".join(problems))
