"""The registry of decision methods by name, read by the command line and the experiments.

It holds names and where each method lives (``module:Class``), not the methods
themselves, so the command line can list the choices without loading numpy. Methods
come from three places:

* the built-in ones, the paper's method and its two baselines;
* other packages, through the entry-point group ``uavtrack.methods``
  (``sequential = "mypackage.methods:SequentialAuction"`` in their pyproject.toml),
  which then appear in ``uavtrack run --method`` and every other command;
* `register`, in a running program (``uavtrack.methods.register(MyMethod())``).
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Any

from ..errors import UsageError

BUILT_IN = {
    "distributed": "uavtrack.methods:Distributed",
    "centralized": "uavtrack.methods:Centralized",
    "greedy": "uavtrack.methods:Greedy",
}
"""The paper's method and its baselines (the reproduction compares exactly these)."""

_REGISTERED: dict[str, Any] = {}


def _plugins() -> dict[str, str]:
    try:
        return {ep.name: ep.value for ep in entry_points(group="uavtrack.methods")}
    except Exception:  # a broken plugin installation must not break the command line
        return {}


def names() -> list[str]:
    """Every method name: built-in first, then plugins, then those registered here."""
    return list(dict.fromkeys([*BUILT_IN, *_plugins(), *_REGISTERED]))


def register(method: Any) -> Any:
    """Add a method instance under its ``name`` for this process; returns it."""
    name = getattr(method, "name", None)
    if not isinstance(name, str) or not name:
        raise ValueError("a method needs a name")
    _REGISTERED[name] = method
    return method


POLICY = "policy:"
"""A name that starts so is a learned policy's file, or a shipped one by name:
``policy:FILE``."""
POLICIES = "uavtrack.env.policy:PolicyMethod"
"""Where the method of a ``policy:FILE`` name lives (made with that name)."""


def load(name: str) -> Any:
    """The method registered under `name` (an instance), loading its module if needed;
    ``policy:FILE`` a learned policy (`uavtrack.env.policy.PolicyMethod`)."""
    if name in _REGISTERED:
        return _REGISTERED[name]
    if name.startswith(POLICY):  # loaded as a plugin is, and read anew: its file may change
        module, _, attribute = POLICIES.partition(":")
        return getattr(importlib.import_module(module), attribute)(name)
    where = BUILT_IN.get(name) or _plugins().get(name)
    if where is None:
        raise ValueError(f"unknown method {name!r}; choose one of: {', '.join(names())}")
    module, _, attribute = where.partition(":")
    try:
        method = getattr(importlib.import_module(module), attribute)
        method = method() if isinstance(method, type) else method
    except Exception as exc:  # a plugin's own failure, named in one line
        raise UsageError(
            f"method {name!r} cannot be loaded from {where}: {type(exc).__name__}: {exc}"
        ) from None
    _REGISTERED[name] = method
    return method
