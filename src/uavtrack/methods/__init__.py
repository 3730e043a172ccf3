"""The paper's method and its two baselines, one interface, chosen by name.

A method decides two things in the cycle: how the UAVs' local estimates are fused
(`fuse`) and how bids become an assignment of UAVs to targets (`assign`). Everything
else (sensing, filtering, planning, control) is shared. Both talk over the cycle's
`radio.Radio`, so lost and late messages reach every method the same way.

* ``distributed`` (the paper's): the D_i flooding protocol and max-consensus over the
  radio with per-UAV stopping, then beacons and bids to one-hop neighbours and each
  UAV's Hungarian auction over its neighbourhood (`assignment.local`).
* ``centralized``: every UAV uploads its tables to a central node whatever the radio
  range; the node takes the most confident estimate of each target over the team
  (max-consensus on the complete graph), plans for every UAV it heard from and solves
  one global assignment, and sends each UAV the fused estimates and its target.
* ``greedy``: the same fusion as distributed; each UAV takes the target of its own
  highest bid, with no interaction.

Faults (`config.FaultModel`): a lost bid leaves the receiver with the last bid it held
of that neighbour (or, with ``robust.stale``, drops the neighbour from its auction); a
lost upload leaves the UAV out of the central fusion and assignment; a lost download
leaves the UAV with its own estimates and its previous target. A failed UAV takes part
in nothing.

A new auction rule plugs in by subclassing `Distributed` and replacing `solve` (see
examples/custom_method.py); `register` adds a method to the `registry` the command line
and the experiments read, and other packages can add theirs by entry point.

Modules: `base` (the interface, `Method`, and what it sees, `Inputs`), `distributed`,
`centralized`, `greedy`, `builtin` (the three by name) and `registry` (every method by
name, the entry points' included).
"""

import importlib
from typing import TYPE_CHECKING

_WHERE = {
    "METHODS": "builtin", "get": "builtin", "register": "builtin",
    "Method": "base", "Inputs": "base", "Fused": "base", "Assigned": "base", "Held": "base",
    "Setting": "base", "consensus": "base", "gated": "base",
    "Distributed": "distributed", "bid_view": "distributed",
    "Centralized": "centralized", "central_node": "centralized",
    "nothing_heard": "centralized", "take_download": "centralized",
    "Greedy": "greedy",
}  # fmt: skip
"""Where each public name lives. They load on first use, so that `registry` (which the
command line reads to list the choices) comes without numpy."""


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'uavtrack.methods' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


if TYPE_CHECKING:
    from .base import Assigned, Fused, Held, Inputs, Method, Setting, consensus, gated
    from .builtin import METHODS, get, register
    from .centralized import Centralized, central_node, nothing_heard, take_download
    from .distributed import Distributed, bid_view
    from .greedy import Greedy

__all__ = [  # noqa: RUF022 (the interface, the methods, then their stages)
    "METHODS", "Method", "Inputs", "Fused", "Assigned", "Held", "Setting", "get", "register",
    "Distributed", "Centralized", "Greedy",
    "consensus", "gated", "bid_view", "central_node", "nothing_heard", "take_download",
]  # fmt: skip
