"""The fault model: message loss (independent or in bursts), UAV failures, position error.

The paper (Sec. 8) leaves open what happens when messages are lost or late, UAVs fail
and their positions are uncertain. This module realises those faults for a batch of
trials, as pure functions of (trial, step, what, sender, receiver): any process (the
batch simulator, a UAV agent, the world program) can tell whether a given message is
lost without sharing a random stream or an order of draws.

The realisation is Philox4x32-10 (Salmon et al., "Parallel random numbers: as easy as
1, 2, 3", SC'11), a counter-based generator: the 128-bit counter holds (step, what and
round, sender, receiver), the 64-bit key comes from the trial's own fault stream (the
third child of its SeedSequence), so adding faults changes neither the targets nor the
sensor noise, and every method sees the same fault realisation (paired comparisons).

* Independent loss (``burst_length`` 1): each message (directed link, protocol, round,
  step) is lost with probability ``loss``.
* Bursts (``burst_length`` > 1): each directed link is a Gilbert-Elliott channel, good
  or bad for a whole cycle, starting in its stationary state. A bad link loses every
  message of the cycle. From good it turns bad with probability p, from bad good with
  r = 1 / burst_length (the mean length of a bad spell), p = loss r / (1 - loss), so
  the long-run loss is ``loss``.
* Failures: a UAV fails for good at a step drawn with probability ``failure_rate`` per
  UAV and cycle, or at the steps listed in ``failures``; from then on it neither senses
  nor sends nor counts as observing.
* Position error: each UAV believes it is at its true ground position plus
  N(0, position_std^2) per axis, drawn per UAV and cycle.
"""

# Strict typing (pyproject.toml), less rules the strict list cannot turn off: the unknown
# types, as numpy resolves an overloaded call with an argument of type Any (every array
# shape is tuple[Any, ...]) to Unknown; constant redefinition, as matrices keep the
# paper's capital names (A, P, R) when rebound.
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false, reportUnknownLambdaType=false
# pyright: reportConstantRedefinition=false

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .config import FaultModel
from .world import believed, children

PROTOCOLS = {"beacon": 1, "flood": 2, "consensus": 3, "bids": 4, "upload": 5, "download": 6}
"""Message kinds; each draws its own losses."""
_LINK, _FAILURE, _POSITION = 16, 17, 18  # draws that are not messages
CENTRAL = 0xFFFFFFFF
"""The central node's identifier in the counters of uploads and downloads."""

_M0, _M1 = np.uint64(0xD2511F53), np.uint64(0xCD9E8D57)
_W0, _W1 = np.uint64(0x9E3779B9), np.uint64(0xBB67AE85)
_LOW = np.uint64(0xFFFFFFFF)


def philox(counter: tuple[ArrayLike, ...], key: tuple[ArrayLike, ...]) -> tuple[np.ndarray, ...]:
    """Philox4x32-10 of the counters (c0, c1, c2, c3) under the keys (k0, k1).

    Each argument is an array of uint32 (or broadcastable to one); returns the four
    output words. Tested against the Random123 known-answer vectors.
    """
    c0, c1, c2, c3 = (np.asarray(c, dtype=np.uint32) for c in counter)
    k0, k1 = (np.asarray(k, dtype=np.uint32).astype(np.uint64) for k in key)
    c0, c1, c2, c3 = np.broadcast_arrays(c0, c1, c2, c3)
    for r in range(10):
        if r:  # the key schedule (a Weyl sequence), modulo 2^32
            k0, k1 = (k0 + _W0) & _LOW, (k1 + _W1) & _LOW
        p0 = _M0 * c0.astype(np.uint64)
        p1 = _M1 * c2.astype(np.uint64)
        hi0, lo0 = (p0 >> np.uint64(32)).astype(np.uint32), (p0 & _LOW).astype(np.uint32)
        hi1, lo1 = (p1 >> np.uint64(32)).astype(np.uint32), (p1 & _LOW).astype(np.uint32)
        c0, c1 = hi1 ^ c1 ^ k0.astype(np.uint32), lo1
        c2, c3 = hi0 ^ c3 ^ k1.astype(np.uint32), lo0
    return c0, c1, c2, c3


def uniform(
    key: np.ndarray, step: ArrayLike, what: ArrayLike, sender: ArrayLike, receiver: ArrayLike
) -> np.ndarray:
    """Uniform numbers in [0, 1) (53 bits), one per broadcast element of the counters.

    key: (..., 2) uint32 per element (the trial's key, broadcast).
    """
    w0, w1, _, _ = philox((step, what, sender, receiver), (key[..., 0], key[..., 1]))
    high = (w0 >> np.uint32(5)).astype(np.float64)  # 27 bits
    low = (w1 >> np.uint32(6)).astype(np.float64)  # 26 bits
    return (high * 67108864.0 + low) / 9007199254740992.0


def what(protocol: str, round_: int | np.ndarray = 0) -> np.ndarray:
    """The counter word naming a message kind and its round."""
    return np.uint32(PROTOCOLS[protocol] << 24) | np.asarray(round_, dtype=np.uint32)


def trial_key(seed: np.random.SeedSequence) -> np.ndarray:
    """A trial's 64-bit fault key, (2,) uint32, from its fault stream."""
    return seed.generate_state(2, np.uint32)


@dataclass(frozen=True)
class Faults:
    """The fault realisation of a batch of trials.

    model: the scenario's `FaultModel`; key: (B, 2) uint32, one per trial; n: UAVs.
    """

    model: FaultModel
    key: np.ndarray
    n: int

    @property
    def active(self) -> bool:
        """Whether any fault can happen (otherwise the cycle takes its fault-free path)."""
        m = self.model
        return bool(
            m.loss > 0
            or m.delay > 0
            or m.round_budget is not None
            or m.failure_rate > 0
            or m.failures
            or m.position_std > 0
        )

    @property
    def bursty(self) -> bool:
        return self.model.burst_length > 1 and 0 < self.model.loss < 1

    def lost(
        self,
        step: int,
        protocol: str,
        round_: int,
        trial: np.ndarray | int,
        sender: np.ndarray,
        receiver: np.ndarray,
        bad: np.ndarray | None = None,
    ) -> np.ndarray:
        """Whether each message (trial, sender -> receiver) of this step, protocol and
        round is lost. UAVs are 0 .. N-1 and the central node is N. `bad` (B, N+1, N+1)
        [trial, receiver, sender] holds the link states of bursty channels at this step."""
        loss = self.model.loss
        shape = np.broadcast(trial, sender, receiver).shape
        if loss <= 0:
            return np.zeros(shape, dtype=bool)
        if loss >= 1:
            return np.ones(shape, dtype=bool)
        if self.bursty:
            if bad is None:
                raise ValueError("bursty losses need the link states `bad` (Faults.link_states)")
            return np.broadcast_to(bad[trial, receiver, sender], shape)
        ids = [np.where(np.asarray(x) == self.n, CENTRAL, x) for x in (sender, receiver)]
        u = uniform(self.key[trial], step, what(protocol, round_), *ids)
        return u < loss

    def link_states(self, step: int, bad: np.ndarray | None) -> np.ndarray | None:
        """Gilbert-Elliott states of every directed link at `step`, (B, N+1, N+1) bool
        [trial, receiver, sender] (True: bad; node N is the central node), from the
        states of the step before."""
        if not self.bursty:
            return None
        loss, r = self.model.loss, 1.0 / self.model.burst_length
        p = loss * r / (1.0 - loss)
        B, n = self.key.shape[0], self.n
        trial, receiver, sender = np.ogrid[:B, : n + 1, : n + 1]
        ids = [np.where(x == n, CENTRAL, x) for x in (sender, receiver)]
        u = uniform(self.key[trial], step, np.uint32(_LINK << 24), *ids)
        if bad is None:  # the stationary distribution
            return u < loss
        return np.where(bad, u >= r, u < p)

    def alive(self, step: int, alive: np.ndarray) -> np.ndarray:
        """Which UAVs are alive at `step` given those alive at the step before, (B, N)."""
        out = alive.copy()
        for uav, when in self.model.failures:
            if when == step:
                out[:, uav] = False
        rate = self.model.failure_rate
        if rate > 0:
            B, n = alive.shape
            trial, uav = np.ogrid[:B, :n]
            u = uniform(self.key[trial], step, np.uint32(_FAILURE << 24), uav, 0)
            out &= u >= rate
        return out

    def position_error(self, step: int) -> np.ndarray | None:
        """Each UAV's GPS error (B, N, 2) [m] at `step` (Box-Muller on two uniforms)."""
        std = self.model.position_std
        if std <= 0:
            return None
        B, n = self.key.shape[0], self.n
        trial, uav = np.ogrid[:B, :n]
        w0, w1, _, _ = philox(
            (step, np.uint32(_POSITION << 24), uav, 0), (self.key[trial, 0], self.key[trial, 1])
        )
        u1 = ((w0 >> np.uint32(8)).astype(np.float64) + 1.0) / 16777217.0  # in (0, 1)
        u2 = (w1 >> np.uint32(8)).astype(np.float64) / 16777216.0
        radius = std * np.sqrt(-2.0 * np.log(u1))
        return np.stack([radius * np.cos(2 * np.pi * u2), radius * np.sin(2 * np.pi * u2)], -1)


def navigation(
    model: FaultModel, seed: int | np.random.SeedSequence, uavs: np.ndarray
) -> np.ndarray:
    """The states (T, N, 5) a trial's UAVs believed at each step, their true states `uavs`
    (T, N, 5) plus the GPS error its fault stream draws (``faults.position_std``; the
    same as the run's: `Faults.position_error` of the trial's key)."""
    if model.position_std <= 0:
        return uavs
    key = trial_key(children(seed)[2])[None]
    faults = Faults(model, key, uavs.shape[1])
    out = np.empty_like(uavs)
    for k in range(len(uavs)):
        error = faults.position_error(k)
        assert error is not None  # position_std > 0
        out[k] = believed(uavs[k], error[0])
    return out
