"""Chi-square quantiles without scipy: the gates and the NEES interval of a run.

For k degrees of freedom the distribution function is the regularised lower incomplete
gamma function P(k/2, x/2), which has a closed form when k is an integer:

- k even: 1 - exp(-x/2) * sum_{i < k/2} (x/2)^i / i!
- k odd:  erf(sqrt(x/2)) - exp(-x/2) * sum_{i < (k-1)/2} (x/2)^(i+1/2) / Gamma(i + 3/2)

The upper tail 1 - P is summed from these forms for x/2 >= k/2 + 1 and the lower one
from P's power series below, every term positive either way (no cancellation).

`ppf` inverts it by bisection to the last bit, so the quantiles agree with
`scipy.stats.chi2.ppf` to a few units in the last place (tests/test_chisquare.py), and a
run that gates or scores the NEES loads neither `scipy.stats` (about half a second of CPU)
nor `scipy.special`.
"""

from __future__ import annotations

import math
from functools import cache


def cdf(x: float, dof: int) -> float:
    """P(X <= x) for X chi-square with `dof` (a positive integer) degrees of freedom."""
    _check(dof)
    if x <= 0.0:
        return 0.0
    half, a = x / 2.0, dof / 2.0
    return _lower(half, a) if half < a + 1.0 else 1.0 - _upper(half, dof)


def sf(x: float, dof: int) -> float:
    """P(X > x), computed without the cancellation of 1 - cdf in the upper tail."""
    _check(dof)
    if x <= 0.0:
        return 1.0
    half, a = x / 2.0, dof / 2.0
    return 1.0 - _lower(half, a) if half < a + 1.0 else _upper(half, dof)


def _lower(h: float, a: float) -> float:
    """P(a, h) by its power series, every term positive (used for h < a + 1)."""
    term = total = 1.0
    n = 0
    while term > total * 1e-17:
        n += 1
        term *= h / (a + n)
        total += term
    return total * math.exp(a * math.log(h) - h - math.lgamma(a + 1.0))


def _upper(h: float, dof: int) -> float:
    """Q(dof/2, h) = 1 - P by the closed forms of the module docstring, every term
    positive (used for h >= dof/2 + 1)."""
    if dof % 2 == 0:
        term = total = 1.0
        for i in range(1, dof // 2):
            term *= h / i
            total += term
        return total * math.exp(-h)
    root = math.sqrt(h)
    term = 2.0 * root / math.sqrt(math.pi)  # h^(1/2) / Gamma(3/2)
    total = 0.0
    for i in range((dof - 1) // 2):
        total += term
        term *= h / (i + 1.5)
    return math.erfc(root) + total * math.exp(-h)


@cache
def ppf(probability: float, dof: int) -> float:
    """The quantile x with cdf(x, dof) = probability, 0 < probability < 1: bisection to
    the last bit on cdf below the median and on sf above it."""
    _check(dof)
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {probability}")
    if dof == 2:
        return -2.0 * math.log1p(-probability)
    upper = probability > 0.5
    goal = 1.0 - probability if upper else probability

    def below(x: float) -> bool:  # whether the quantile lies above x
        return sf(x, dof) > goal if upper else cdf(x, dof) < goal

    low, high = 0.0, float(dof)
    while below(high):
        low, high = high, 2.0 * high
    while True:
        mid = 0.5 * (low + high)
        if mid in (low, high):
            return high
        if below(mid):
            low = mid
        else:
            high = mid


def _check(dof: int) -> None:
    if int(dof) != dof or dof < 1:
        raise ValueError(f"degrees of freedom must be a positive integer, got {dof}")
