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
"""

from __future__ import annotations

from ..errors import UsageError
from . import registry
from .base import Assigned, Fused, Held, Inputs, Method, Setting, consensus, gated
from .centralized import Centralized, central_node, nothing_heard, take_download
from .distributed import Distributed, bid_view
from .greedy import Greedy

METHODS: dict[str, Method] = {
    m.name: registry.register(m) for m in (Distributed(), Centralized(), Greedy())
}
"""The built-in methods by name; `registry` holds every method (plugins and `register`)."""


def register(method: Method) -> Method:
    """Make `method` available by its name (in this process) and return it."""
    if not isinstance(method, Method):
        raise TypeError(f"a method must be a uavtrack.methods.Method, not {type(method).__name__}")
    return registry.register(method)


def get(method: str | Method) -> Method:
    """A method by name (``distributed``, ``centralized``, ``greedy``, or any registered)
    or an instance."""
    if isinstance(method, Method):
        return method
    if not isinstance(method, str):
        raise ValueError(f"unknown method {method!r}; choose one of: {', '.join(registry.names())}")
    found = registry.load(method)
    if not isinstance(found, Method):
        raise UsageError(
            f"method {method!r} is a {type(found).__name__}, not a uavtrack.methods.Method"
        )
    return found


__all__ = [  # noqa: RUF022 (the interface, the methods, then their stages)
    "METHODS", "Method", "Inputs", "Fused", "Assigned", "Held", "Setting", "get", "register",
    "Distributed", "Centralized", "Greedy",
    "consensus", "gated", "bid_view", "central_node", "nothing_heard", "take_download",
]  # fmt: skip
