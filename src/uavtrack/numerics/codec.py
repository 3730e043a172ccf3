"""How an estimate travels in a listed consensus message (``radio.encoding``).

An estimate is a mean (4,) and a covariance (4, 4). A `Codec` packs them into the arrays
a message carries and unpacks what arrives; the batch uses what arrives
(`Codec.delivered`), so a swarm and `uavtrack run` fuse the same numbers.

* ``compact``: the mean in float32 and the covariance's upper triangle in float32
  (56 bytes of numbers).
* ``quantized``: the mean in float16, the covariance as four log-variances (int16, 1/256
  of an octave each) and six correlations (int8, 1/127 each): 22 bytes of numbers. The
  coding is *conservative*: what arrives is an estimate with a covariance at least the
  sender's, so fusion stays consistent (as in Funk, Noack and Hanebeck, Sensors 21(9):3059,
  2021). The float16 rounding e of the mean is known to the sender, which adds e e^T to
  the covariance (the error of the mean that arrives is the estimate's error less e).
  Variances round up; correlations round to the nearest code, after any correlation
  matrix too close to singular is shrunk toward the identity (`NEAR_SINGULAR`, `FLOOR`:
  the rounding cannot make it indefinite). Then every log-variance is raised by the same
  number of codes until the decoded covariance dominates the one it codes (its
  generalized eigenvalues against it at most 1, to `TOLERANCE`). A decoded estimate
  coded again gives the same codes, so a tuple passed on arrives as it first did.
"""

# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["CODECS", "COMPACT", "QUANTIZED", "Codec", "mirrored", "upper"]

Field = tuple[str, tuple[int, ...], str]
"""An array of a message's content: (dtype, shape, domain) (as `radio.Field`)."""

_UPPER = np.triu_indices(4)
_OFF = np.triu_indices(4, k=1)

STEPS = 256
"""Codes per octave of a quantized variance: a variance rounds up by at most 0.27 %."""
SCALE = 127
"""Codes per unit of a quantized correlation: it rounds by at most 1 / 254."""
NEAR_SINGULAR = 0.03
"""Smallest eigenvalue of every correlation matrix the quantized encoding sends: one
whose rounding falls below it is shrunk toward the identity to `FLOOR` and rounded
again. Rounding moves each of the 12 off-diagonal entries by at most 1 / 254, so the
eigenvalues by at most sqrt(12) / 254 = 0.0136 (Weyl): the shrunk one rounds to at
least 0.036. A decoded matrix rounds to itself, so a receiver that passes it on sends
the same codes."""
FLOOR = 0.05
"""The smallest eigenvalue a near-singular correlation matrix is shrunk to."""
LARGEST = float(np.finfo(np.float16).max)
"""The largest float16 (65504): a mean beyond it is sent at it."""
TOLERANCE = 1e-6
"""Codes a variance or the dominance factor may exceed a whole code by and still round
to it: a decoded estimate coded again gives the same codes (a relay changes nothing),
at a cost of a relative 3e-9 in the dominance the coding keeps."""


def upper(cov: np.ndarray) -> np.ndarray:
    """The upper triangle (..., 10) of covariances (..., 4, 4), row by row."""
    return cov[..., _UPPER[0], _UPPER[1]]


def mirrored(triangle: np.ndarray) -> np.ndarray:
    """Covariances (..., 4, 4), float64, from their upper triangle (..., 10) (`upper`)."""
    full = np.zeros((*triangle.shape[:-1], 4, 4))
    full[..., _UPPER[0], _UPPER[1]] = triangle
    full[..., _UPPER[1], _UPPER[0]] = triangle
    return full


@dataclass(frozen=True)
class Codec:
    """One way an estimate travels: `fields(domain)` its arrays by name, (dtype, shape
    per row, domain), the mean's domain given (a target's or a track's estimate);
    `pack(mean, cov)` those arrays of means (..., 4) and covariances (..., 4, 4);
    `unpack(arrays)` the means and covariances that arrive, in float64."""

    name: str
    fields: Callable[[str], dict[str, Field]]
    pack: Callable[[np.ndarray, np.ndarray], dict[str, np.ndarray]]
    unpack: Callable[[dict[str, np.ndarray]], tuple[np.ndarray, np.ndarray]]

    def delivered(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The means and covariances (..., 4), (..., 4, 4) as they arrive."""
        return self.unpack(self.pack(mean, cov))


def _compact_fields(domain: str) -> dict[str, Field]:
    return {
        "mean": ("<f4", (-1, 4), domain),
        "cov": ("<f4", (-1, 10), "covariance triangle"),
    }


def _compact_pack(mean: np.ndarray, cov: np.ndarray) -> dict[str, np.ndarray]:
    return {"mean": mean.astype("<f4"), "cov": upper(cov).astype("<f4")}


def _compact_unpack(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return arrays["mean"].astype(np.float64), mirrored(arrays["cov"])


COMPACT = Codec("compact", _compact_fields, _compact_pack, _compact_unpack)


def _quantized_fields(domain: str) -> dict[str, Field]:
    return {
        "mean": ("<f2", (-1, 4), domain),
        "var": ("<i2", (-1, 4), "log variances"),
        "corr": ("|i1", (-1, 6), "correlations"),
    }


def correlations(corr: np.ndarray) -> np.ndarray:
    """The correlation matrices (..., 4, 4) of correlation codes (..., 6)."""
    out = np.zeros((*corr.shape[:-1], 4, 4))
    value = corr.astype(np.float64) / SCALE
    out[..., _OFF[0], _OFF[1]] = value
    out[..., _OFF[1], _OFF[0]] = value
    out[..., np.arange(4), np.arange(4)] = 1.0
    return out


def decoded_cov(var: np.ndarray, corr: np.ndarray) -> np.ndarray:
    """Covariances (..., 4, 4) of log-variance codes (..., 4) and correlation codes
    (..., 6): D^(1/2) C D^(1/2), D = 2^(var / STEPS)."""
    sd = np.exp2(var.astype(np.float64) / (2 * STEPS))
    return correlations(corr) * sd[..., :, None] * sd[..., None, :]


def _rounded(C: np.ndarray) -> np.ndarray:
    """The correlation codes (..., 6) of correlation matrices (..., 4, 4)."""
    return np.clip(np.rint(C[..., _OFF[0], _OFF[1]] * SCALE), -SCALE, SCALE).astype("|i1")


def _quantized_pack(mean: np.ndarray, cov: np.ndarray) -> dict[str, np.ndarray]:
    # beyond float16's range a mean is sent at its edge, the difference in e e^T below
    small = np.clip(mean, -LARGEST, LARGEST).astype("<f2")
    error = small.astype(np.float64) - mean
    P = cov + error[..., :, None] * error[..., None, :]  # the error of the mean that arrives
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    # a slot without an estimate (an empty track, no covariance) is coded as the identity:
    # no receiver reads it, and every array of a batch is coded at once
    usable = np.asarray(
        np.isfinite(P).all(axis=(-2, -1))
        & np.isfinite(small.astype(np.float64)).all(axis=-1)
        & (np.diagonal(P, axis1=-2, axis2=-1) > 0).all(axis=-1)
    )
    if not usable.all():
        P = np.where(usable[..., None, None], P, np.eye(4))
    variance = np.diagonal(P, axis1=-2, axis2=-1)
    sd = np.sqrt(variance)
    C = P / (sd[..., :, None] * sd[..., None, :])
    corr = _rounded(C)
    low = np.linalg.eigvalsh(C)[..., 0]
    near = np.linalg.eigvalsh(correlations(corr))[..., 0] < NEAR_SINGULAR
    if near.any():  # shrunk toward the identity, then rounded again
        shrink = np.clip((FLOOR - low) / np.maximum(1.0 - low, 1e-12), 0.0, 1.0)
        shrink = np.where(near, shrink, 0.0)[..., None, None]
        corr = np.where(near[..., None], _rounded((1.0 - shrink) * C + shrink * np.eye(4)), corr)
    var = np.ceil(np.log2(variance) * STEPS - TOLERANCE)
    # dominance: the largest generalized eigenvalue of P against the decoded covariance
    lower = np.linalg.cholesky(decoded_cov(var, corr))
    inverse = np.linalg.inv(lower)
    factor = np.linalg.eigvalsh(inverse @ P @ np.swapaxes(inverse, -1, -2))[..., -1]
    raise_by = np.ceil(np.log2(np.maximum(factor, 1.0)) * STEPS - TOLERANCE)
    var = var + np.maximum(raise_by, 0.0)[..., None]
    # int16 holds variances in [2^-128, 2^128): below, the code of 2^-128 (larger: still
    # conservative); above, that of 2^128, which every run's plausibility bound refuses
    var = np.clip(var, np.iinfo(np.int16).min, np.iinfo(np.int16).max)
    return {"mean": small, "var": var.astype("<i2"), "corr": corr}


def _quantized_unpack(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return arrays["mean"].astype(np.float64), decoded_cov(arrays["var"], arrays["corr"])


QUANTIZED = Codec("quantized", _quantized_fields, _quantized_pack, _quantized_unpack)

CODECS = {codec.name: codec for codec in (COMPACT, QUANTIZED)}
"""The codecs by ``radio.encoding`` (the full encoding carries float64 as they are)."""
