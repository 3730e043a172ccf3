"""Long statistical checks (pytest -m slow)."""

import numpy as np
import pytest

import uavtrack
from uavtrack.experiments.jobs import compare

from .test_estimation import nees_runs

pytestmark = pytest.mark.slow


def test_paper_ordering_on_paired_trials():
    # the paper's finding on the default scenario: distributed beats greedy, and
    # centralized, with everyone's data, is at least as good as distributed
    result = compare(uavtrack.Scenario(), ["distributed", "centralized", "greedy"], 30)
    rate = {m: r["observation_rate"] for m, r in result.items()}
    gain = rate["distributed"] - rate["greedy"]
    assert gain.mean() > 3 * gain.std(ddof=1) / np.sqrt(len(gain))
    loss = rate["centralized"] - rate["distributed"]
    assert loss.mean() > -2 * loss.std(ddof=1) / np.sqrt(len(loss))


def test_nees_within_ten_percent_with_many_runs():
    # 200 runs resolve the small optimism of converted measurements (R evaluated at the
    # noisy measurement, eq. 10-12): the filter stays within 10% of consistency
    runs = nees_runs(200, 60)
    assert 3.6 < runs.mean() < 4.4
    per_step = runs.mean(axis=0)
    assert (per_step > 3.2).all() and (per_step < 5.0).all()
