"""The built-in methods by name (`METHODS`), and `get` and `register`, which every
part of uavtrack uses to find a method: by name, among the built-in ones, the
registered ones and those of other packages (entry points, `registry`).
"""

from __future__ import annotations

from ..errors import UsageError
from . import registry
from .base import Method
from .centralized import Centralized
from .distributed import Distributed
from .greedy import Greedy

METHODS: dict[str, Method] = {
    m.name: registry.register(m) for m in (Distributed(), Centralized(), Greedy())
}
"""The built-in methods by name; `registry` holds every method (plugins and `register`)."""


def register(method: Method) -> Method:
    """Make `method` available by its name (in this process) and return it."""
    # for callers whose types no checker saw
    if not isinstance(method, Method):  # pyright: ignore[reportUnnecessaryIsInstance]
        raise TypeError(f"a method must be a uavtrack.methods.Method, not {type(method).__name__}")
    return registry.register(method)


def get(method: str | Method) -> Method:
    """A method by name (``distributed``, ``centralized``, ``greedy``, or any registered)
    or an instance."""
    if isinstance(method, Method):
        return method
    # for callers whose types no checker saw
    if not isinstance(method, str):  # pyright: ignore[reportUnnecessaryIsInstance]
        raise ValueError(f"unknown method {method!r}; choose one of: {', '.join(registry.names())}")
    found = registry.load(method)
    if not isinstance(found, Method):
        raise UsageError(
            f"method {method!r} is a {type(found).__name__}, not a uavtrack.methods.Method"
        )
    return found
