"""A learned policy as a decision method: ``--method policy:FILE`` in every command.

A policy file is a NumPy archive (``.npz``) of a multilayer perceptron that maps one
UAV's observation (`spaces.Spaces`, the Box form) to the logits of its three actions:

* ``W0, b0, W1, b1, ...``: the layers, float32, each ``x @ W + b``; every layer but the
  last is followed by the activation;
* ``meta``: a JSON object: ``format`` (`FORMAT`), ``activation`` (`ACTIVATIONS`),
  ``max_targets`` and ``max_neighbours`` (the observation's rows), and anything the
  trainer records of itself (algorithm, frames, seed, the rate it reached).

A graph policy (``mappo-gnn``) has a first layer over the radio graph, as BenchMARL's
graph network with PyTorch Geometric's ``GraphConv`` computes it: ``G_root, G_rel,
G_b``, each UAV's ``x @ G_root + (the sum of its neighbours' x) @ G_rel + G_b``, its
neighbours the UAVs within r_C of where their observations say they are
(`Spaces.positions`, whatever the radio delivers); then the perceptron's layers, the
first of them reading that sum directly (no activation between, as BenchMARL chains
its models). It reads the whole team's observations, so only the batch runs it (not
the agent form).

Each UAV flies the action of its largest logit (the lowest index on ties), so a policy
is deterministic: the same seed gives the same trial. The team fuses as the paper's
method does (max-consensus over the radio) and runs no planner and no auction: the
policy is the whole decision. The cycle is the simulator's own (`simulation.decide`
without planning; `simulation.chosen`, where the UAVs send each other beacons of their
whole states, counted with the cycle's messages and bytes, and the policy reads its
neighbours from those that arrived; `simulation.finish` with the policy's actions), so
every metric and fault of a run applies. A UAV's "in view" is what it measured.

Shipped policies live in this package's ``policies`` folder and are named without a
path or suffix (``policy:NAME``); any other ``policy:PATH`` is a file.

Needs the env extra (its observation builder uses gymnasium's spaces).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..errors import UsageError
from ..methods.distributed import Distributed
from ..records import Pending, State
from .episodes import view_of
from .spaces import Spaces, View

__all__ = [
    "ACTIVATIONS", "FORMAT", "GRAPH", "PREFIX", "SHIPPED", "Policy", "PolicyMethod", "digest",
    "shipped",
]  # fmt: skip

FORMAT = 1
"""The version of the policy file's layout."""

PREFIX = "policy:"
"""What a method name starts with when it names a policy."""

SHIPPED = Path(__file__).with_name("policies")
"""The folder of the shipped policies (``policy:NAME``)."""

ACTIVATIONS = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
}
"""The hidden layers' activations, by name."""


def digest(spec: str) -> str:
    """The SHA-256 of the file a policy's method name (``policy:FILE``) names, for a
    results folder to tell two files of one name apart."""
    path = _path(spec.removeprefix(PREFIX))
    if not path.is_file():
        raise UsageError(
            f"no policy file {path} (shipped policies: {', '.join(shipped()) or 'none'})"
        )
    return hashlib.sha256(path.read_bytes()).hexdigest()


def shipped() -> list[str]:
    """The names of the shipped policies."""
    return sorted(p.stem for p in SHIPPED.glob("*.npz"))


def _path(spec: str) -> Path:
    """The file `spec` names: a shipped policy by bare name, or a path."""
    path = Path(spec)
    if path.name == spec and not path.suffix and (SHIPPED / f"{spec}.npz").is_file():
        return SHIPPED / f"{spec}.npz"
    return path


GRAPH = ("G_root", "G_rel", "G_b")
"""The arrays of a graph policy's first layer (see the module)."""


@dataclass(frozen=True, kw_only=True)
class Policy:
    """A multilayer perceptron over one UAV's observation: layers [(W, b)], the hidden
    activation's name and the observation's rows; meta holds the trainer's record. With
    graph (root (D, H), rel (D, H), bias (H,)), a first layer over the radio graph."""

    layers: list[tuple[np.ndarray, np.ndarray]]
    activation: str = "tanh"
    max_targets: int = 4
    max_neighbours: int = 4
    meta: dict[str, Any] = field(default_factory=dict)
    graph: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def __post_init__(self) -> None:
        if self.activation not in ACTIVATIONS:
            raise ValueError(
                f"activation must be one of {', '.join(ACTIVATIONS)}, not {self.activation!r}"
            )
        if not self.layers:
            raise ValueError("a policy needs at least one layer")
        width = self.layers[0][0].shape[0]
        if self.graph is not None:
            root, rel, bias = self.graph
            chained = root.ndim == 2 and root.shape == rel.shape and bias.shape == (width,)
            if not chained or root.shape[1] != width:
                raise ValueError(f"the graph layer {root.shape}, {rel.shape}, {bias.shape} "
                                 f"does not chain to a first layer of {width} inputs")  # fmt: skip
            if not all(np.issubdtype(a.dtype, np.floating) and np.isfinite(a).all()
                       for a in self.graph):  # fmt: skip
                raise ValueError("the graph layer holds a value that is not a finite float")
        for i, (W, b) in enumerate(self.layers):
            real = all(np.issubdtype(a.dtype, np.floating) for a in (W, b))
            if not real:
                raise ValueError(
                    f"layer {i}: W and b must be real floats, not {W.dtype}, {b.dtype}"
                )
            if W.ndim != 2 or b.shape != (W.shape[1],) or W.shape[0] != width:
                raise ValueError(f"layer {i}: W {W.shape} and b {b.shape} do not chain")
            if not (np.isfinite(W).all() and np.isfinite(b).all()):
                raise ValueError(f"layer {i} holds a value that is not finite")
            width = W.shape[1]
        if width != 3:
            raise ValueError(f"the last layer gives {width} logits; the actions are 3")

    @property
    def inputs(self) -> int:
        """The size of the observation it reads."""
        first = self.layers[0][0] if self.graph is None else self.graph[0]
        return int(first.shape[0])

    def logits(self, observation: np.ndarray, spaces: Spaces | None = None) -> np.ndarray:
        """The logits (..., 3) of observations (..., inputs); a graph policy's of the
        team's observations (..., N, inputs) built by `spaces` (its scales and r_C)."""
        x = np.asarray(observation, dtype=np.float32)
        if x.shape[-1] != self.inputs:
            raise ValueError(f"the policy reads {self.inputs} numbers, not {x.shape[-1]}")
        if self.graph is not None:
            if spaces is None or x.ndim < 2:
                raise ValueError("a graph policy reads the team's observations and their spaces")
            x = self._graph(x, spaces)
        act = ACTIVATIONS[self.activation]
        for i, (W, b) in enumerate(self.layers):
            x = x @ W + b
            if i + 1 < len(self.layers):
                x = act(x)
        return x

    def _graph(self, x: np.ndarray, spaces: Spaces) -> np.ndarray:
        """The graph layer (see the module) of the team's observations x (..., N, D)."""
        root, rel, bias = self.graph  # pyright: ignore[reportGeneralTypeIssues]
        where = spaces.positions(x)
        apart = np.linalg.norm(where[..., :, None, :] - where[..., None, :, :], axis=-1)
        reach = spaces.scenario.comm_range / spaces.half
        n = x.shape[-2]
        linked = (apart <= np.float32(reach)) & ~np.eye(n, dtype=bool)
        summed = linked.astype(np.float32) @ x
        return x @ root + summed @ rel + bias

    def act(self, observation: np.ndarray, spaces: Spaces | None = None) -> np.ndarray:
        """The action (...) of the largest logit of each observation (the lowest on ties)."""
        return np.argmax(self.logits(observation, spaces), axis=-1)

    def spaces(self, scenario: Any) -> Spaces:
        """The observation builder of `scenario` with this policy's rows; a one-line
        error when the scenario's team cannot fill them or the sizes differ."""
        try:
            built = Spaces(scenario, "box", self.max_targets, self.max_neighbours)
        except (ValueError, UsageError) as exc:
            raise UsageError(f"the policy does not fit this scenario: {exc}") from None
        if built.size != self.inputs:
            raise UsageError(
                f"the policy reads {self.inputs} numbers; this scenario's observation has "
                f"{built.size}"
            )
        return built

    def save(self, path: str | Path) -> Path:
        """Write the policy to `path` (``.npz``), whole or not at all."""
        path = Path(path)
        meta = {
            **self.meta,
            "format": FORMAT,
            "activation": self.activation,
            "max_targets": self.max_targets,
            "max_neighbours": self.max_neighbours,
        }
        arrays: dict[str, np.ndarray] = {"meta": np.array(json.dumps(meta, sort_keys=True))}
        for i, (W, b) in enumerate(self.layers):
            arrays[f"W{i}"], arrays[f"b{i}"] = W.astype(np.float32), b.astype(np.float32)
        if self.graph is not None:
            arrays |= {k: a.astype(np.float32) for k, a in zip(GRAPH, self.graph, strict=True)}
        part = path.with_name(path.name + ".part")
        try:
            with open(part, "wb") as f:
                np.savez_compressed(f, **arrays)  # pyright: ignore[reportArgumentType]
            part.replace(path)
        finally:
            part.unlink(missing_ok=True)
        return path

    @classmethod
    def load(cls, spec: str | Path) -> Policy:
        """The policy of a file, or a shipped one by name; a one-line `UsageError` that
        names what is wrong otherwise."""
        path = _path(str(spec))
        if path.is_dir():
            raise UsageError(f"{path} is a folder, not a policy file")
        if not path.is_file():
            names = ", ".join(shipped()) or "none"
            raise UsageError(f"no policy file {path} (shipped policies: {names})")
        try:
            with np.load(path, allow_pickle=False) as data:
                if not hasattr(data, "files"):  # a lone array (.npy), not an archive
                    raise ValueError("one array")
                arrays = {k: data[k] for k in data.files}
        except Exception:  # a file that is no NumPy archive, or one of objects
            raise UsageError(
                f"{path} is not a policy file: not a NumPy archive of arrays (.npz)"
            ) from None
        try:
            meta = json.loads(str(arrays.pop("meta")))
            if not isinstance(meta, dict):
                raise ValueError(f"meta is a {type(meta).__name__}, not a JSON object")
            if meta.get("format") != FORMAT:
                raise ValueError(f"format {meta.get('format')!r}, this version reads {FORMAT}")
            count = sum(1 for k in arrays if k.startswith("W"))
            layers = [(arrays[f"W{i}"], arrays[f"b{i}"]) for i in range(count)]
            graph = None
            if GRAPH[0] in arrays:
                root, rel, bias = (arrays[k] for k in GRAPH)
                graph = (root, rel, bias)
            return cls(
                graph=graph,
                layers=layers,
                activation=meta["activation"],
                max_targets=int(meta["max_targets"]),
                max_neighbours=int(meta["max_neighbours"]),
                meta=meta,
            )
        except (KeyError, ValueError, TypeError, json.JSONDecodeError) as exc:
            raise UsageError(f"{path} is not a policy file: {type(exc).__name__}: {exc}") from None


class PolicyMethod(Distributed):
    """A learned policy as a decision method: the paper's fusion, then each UAV flies
    the action its policy gives its observation (no planner, no auction)."""

    plans: ClassVar[bool] = False

    def __init__(self, spec: str) -> None:
        self.spec = spec.removeprefix(PREFIX)
        self.policy = Policy.load(self.spec)
        self.instance_name = PREFIX + self.spec
        self.local = self.policy.graph is None  # a graph policy reads the whole team
        self._spaces: tuple[Any, Spaces] | None = None  # the last scenario's builder

    @property
    def name(self) -> str:  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.instance_name

    def refusal(self, scenario: Any) -> str | None:
        """Why the policy cannot fly `scenario`: its observation does not fit."""
        try:
            self.policy.spaces(scenario)
        except UsageError as exc:
            return str(exc)
        return None

    def actions(self, state: State, pending: Pending, ctx: Any) -> np.ndarray:
        """The policy's actions (B, N) for the pending cycle (`simulation.chosen`)."""
        return self.choose(view_of(pending, ctx.scenario), ctx.scenario)

    def choose(self, view: View, scenario: Any) -> np.ndarray:
        """The policy's actions (B, N) for a cycle's `View` of `scenario`: the batch's
        (`actions`), or one UAV program's, whose view holds its own row."""
        if self._spaces is None or self._spaces[0] is not scenario:
            self._spaces = (scenario, self.policy.spaces(scenario))
        spaces = self._spaces[1]
        observation = spaces.observe(view)
        assert isinstance(observation, np.ndarray)  # the Box form
        return self.policy.act(observation, spaces)

    def __repr__(self) -> str:
        return f"PolicyMethod({self.spec!r})"
