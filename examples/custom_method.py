"""Plug in your own auction rule (see uavtrack.methods).

This method keeps the paper's max-consensus fusion and message exchange but replaces
the Hungarian assignment each UAV solves over its neighbourhood by a sequential greedy
auction. Only the neighbourhood problem changes: beacons, bids, lost and late messages,
failures (`[faults]` of the scenario) reach it as they reach the paper's method.

    python examples/custom_method.py      # compare it with the paper's method

Importing this module defines the method and runs nothing, so it can be the module of a
plugin package: with ``sequential = "custom_method:SequentialAuction"`` in the package's
``[project.entry-points."uavtrack.methods"]``, every command takes ``--method sequential``
(docs: how-to guides, "Your own method").
"""

import numpy as np

import uavtrack
from uavtrack.methods import Distributed, register


def sequential(bids):
    """Highest remaining (UAV, target) pair first; targets are reused once all are taken.

    bids: (n, m) of the n UAVs of one neighbourhood. Returns (n,) a target per UAV.
    """
    n, m = bids.shape
    choice = np.full(n, -1)
    free = np.ones(m, dtype=bool)
    while (choice < 0).any():
        if not free.any():
            free[:] = True  # more UAVs than targets: another round (Remark 2)
        open_bids = np.where((choice < 0)[:, None] & free[None, :], bids, -np.inf)
        row, col = np.unravel_index(np.argmax(open_bids), open_bids.shape)
        choice[row], free[col] = col, False
    return choice


class SequentialAuction(Distributed):
    """The paper's method with `sequential` as each UAV's neighbourhood rule."""

    name = "sequential"
    solve = staticmethod(sequential)


def main() -> None:
    # registered for this process only: uavtrack.run(scenario, "sequential", ...)
    register(SequentialAuction())
    seeds = [uavtrack.trial_seed(0, t) for t in range(8)]
    for label, scenario in (
        ("no faults", uavtrack.Scenario(steps=200)),
        ("20% loss", uavtrack.Scenario(steps=200).with_overrides({"faults.loss": 0.2})),
    ):
        for method in ("distributed", "sequential", "greedy"):
            rates = uavtrack.run(scenario, method, seeds).metrics["observation_rate"]
            print(f"{label:10s} {method:12s} {rates.mean():.3f}")


if __name__ == "__main__":
    main()
