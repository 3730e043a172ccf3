"""The messages of the agent form: small typed records with a schema version.

Every message is a msgspec ``Struct`` encoded as MessagePack, tagged with its kind, the
schema `VERSION` and the run it belongs to; arrays travel as (dtype, shape, bytes).
`decode` returns None for anything malformed, truncated, of another version or of
another run, and the receiver counts it as dropped: a bad message never stops an agent.

World -> agent: `Hello` (the run's scenario, method and fault key, once), `Sense` (one
cycle's own measurements, believed pose and radio links). Agent -> world: `Report` (the
action and what the trace records). Agent <-> agent: `Radio` (a round of a protocol:
beacon, flood, consensus, bids, upload, download).
"""

from __future__ import annotations

from typing import Any

import msgspec
import numpy as np

VERSION = 2
"""Schema version; a message of another version is dropped."""


class Array(msgspec.Struct, array_like=True, frozen=True):
    """A numpy array on the wire."""

    dtype: str
    shape: tuple[int, ...]
    data: bytes

    @classmethod
    def of(cls, value: Any) -> Array:
        value = np.asarray(value)  # (ascontiguousarray would make a 0-d array 1-d)
        return cls(value.dtype.str, value.shape, value.tobytes(order="C"))

    def array(self) -> np.ndarray:
        dtype = np.dtype(self.dtype)
        if dtype.kind not in "biuf" or dtype.itemsize * int(np.prod(self.shape)) != len(self.data):
            raise ValueError("array does not match its shape")
        return np.frombuffer(self.data, dtype=dtype).reshape(self.shape)


class Hello(msgspec.Struct, tag="hello", frozen=True):
    """The run: its scenario (JSON), method, the trial's fault key, every UAV's prior
    (mean (Nt, 4) and covariance (4, 4)), and the deadline of a round [s]."""

    version: int
    run: str
    scenario: str
    method: str
    key: Array
    prior_mean: Array
    prior_cov: Array
    deadline: float


class Sense(msgspec.Struct, tag="sense", frozen=True):
    """One cycle for one UAV: its believed state (5,), which targets it observes (Nt,)
    and their range-bearing measurements (K, 2), who it can hear this cycle (N,) bool,
    who is alive (N,) bool. alive[uav] False tells the agent it has failed."""

    version: int
    run: str
    k: int
    uav: int
    believed: Array
    observed: Array
    z: Array
    links: Array
    alive: Array


class Tick(msgspec.Struct, tag="tick", frozen=True):
    """One cycle for the central node: who is alive (N,)."""

    version: int
    run: str
    k: int
    alive: Array


class Report(msgspec.Struct, tag="report", frozen=True):
    """A UAV's decision of one cycle and what the trace records of it."""

    version: int
    run: str
    k: int
    uav: int
    action: int
    target: int
    mean: Array
    cov: Array
    bids: Array
    rounds: int
    sent: int
    delivered: int
    decision_ms: float
    published: int = 0
    bytes: int = 0
    dropped: int = 0  # malformed, foreign or old messages this program dropped so far


class Radio(msgspec.Struct, tag="radio", frozen=True):
    """A round of a protocol sent by a UAV (or by the central node, sender N) at cycle
    k. final: the sender has stopped; its content holds for every later round."""

    version: int
    run: str
    k: int
    protocol: str
    round: int
    sender: int
    final: bool
    content: dict[str, Array]


Message = Hello | Sense | Tick | Report | Radio
_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(Message)


def encode(message: Message) -> bytes:
    return _encoder.encode(message)


def decode(payload: bytes, run: str) -> Message | None:
    """The message, or None when it is malformed, of another version or of another run."""
    try:
        message = _decoder.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError, TypeError):
        return None
    if message.version != VERSION or message.run != run:
        return None
    return message


def arrays(content: dict[str, Array]) -> dict[str, np.ndarray] | None:
    """The arrays of a message's content, or None when one is malformed."""
    try:
        return {name: value.array() for name, value in content.items()}
    except (ValueError, TypeError):
        return None


def packed(content: dict[str, Any]) -> dict[str, Array]:
    return {name: Array.of(value) for name, value in content.items()}
