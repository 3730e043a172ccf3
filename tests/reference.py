"""Results stored by an earlier version, and how the suite compares them on another CPU.

"Bit for bit" in this suite means: every integer and boolean result (observations,
assignments, actions, consensus rounds, counters) is exactly equal, and every floating-point
result agrees to `RTOL` of its magnitude. Floating-point sums do not round the same way on
every processor: numpy picks SIMD kernels by CPU (AVX2, AVX-512, ...), and BLAS picks its
own, so an estimate computed on another machine may differ in its last bits (about 1e-14
relative in the stored results below, between an AVX-512 and a baseline SSE path). Within
one machine, two forms of a computation are compared with the tolerances of
`uavtrack.testing`.

A float trace field is stored as a sketch, one number per step: the step's values
projected on fixed weights from an integer hash, which changes when any value of the step
changes by more than rounding. Its `scale` (the largest magnitude in the field) sets the
tolerance.
"""

from __future__ import annotations

import hashlib

import numpy as np

RTOL = 1e-12
"""Floats stored by another run agree to this fraction of their magnitude."""

EXACT_FIELDS = ("observed", "assignment", "action", "rounds")
"""Trace fields that are decisions or counts: stored as digests, compared exactly (an
action is one of the bank angles, a choice, not the result of a sum)."""


def weights(n: int) -> np.ndarray:
    """(n,) fixed weights in [-0.5, 0.5) from Knuth's multiplicative hash: integer
    arithmetic, the same on every machine."""
    i = np.arange(n, dtype=np.uint64)
    return ((i * np.uint64(2654435761) + np.uint64(12345)) % np.uint64(2**32)) / 2.0**32 - 0.5


def sketch(x: np.ndarray) -> tuple[np.ndarray, float]:
    """(T, ...) -> the (T,) per-step projections on `weights`, and the field's scale."""
    flat = np.asarray(x, dtype=float).reshape(len(x), -1)
    return flat @ weights(flat.shape[1]), float(np.abs(flat).max())


def digest(x: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()


def check_field(name: str, x: np.ndarray, stored: dict) -> None:
    """Assert that trace field `x` equals what was stored for it (exactly, or to RTOL)."""
    if "sha256" in stored:
        assert digest(x) == stored["sha256"], f"{name}: not the stored decisions"
        return
    values, _ = sketch(x)
    reference = np.asarray(stored["sketch"])
    bound = RTOL * stored["scale"] * np.abs(weights(np.asarray(x[0]).size)).sum()
    gap = np.abs(values - reference)
    assert values.shape == reference.shape and (gap <= bound).all(), (
        f"{name}: differs from the stored values by up to {gap.max():.3g} at step "
        f"{int(np.argmax(gap))} (tolerance {bound:.3g})"
    )
