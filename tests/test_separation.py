"""Separation between UAVs of one altitude band (`airspace.separation`): the pairs that
count, the losses a run accumulates, and what a run reports, against scipy's distances."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import pdist, squareform

import uavtrack
from uavtrack import cli
from uavtrack.airspace.separation import Separation, close_pairs


def brute_force(uavs, alive, vertical, reach):
    """Every pair by two loops: (trial, i, q) -> horizontal distance."""
    out = {}
    B, n, _ = uavs.shape
    for b in range(B):
        for i in range(n):
            for q in range(i + 1, n):
                d = float(np.hypot(*(uavs[b, i, :2] - uavs[b, q, :2])))
                same_band = abs(uavs[b, i, 2] - uavs[b, q, 2]) < vertical
                if alive[b, i] and alive[b, q] and same_band and d <= reach:
                    out[(b, i, q)] = d
    return out


def as_dict(found):
    trial, i, q, d = found
    return {(int(b), int(x), int(y)): float(v) for b, x, y, v in zip(trial, i, q, d, strict=True)}


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    batch=st.integers(1, 3),
    n=st.integers(1, 40),
    spread=st.sampled_from([20.0, 200.0, 2000.0]),
    reach=st.sampled_from([5.0, 50.0, 300.0]),
)
def test_close_pairs_are_every_pair_of_a_band_within_reach_in_both_forms(
    seed, batch, n, spread, reach
):
    rng = np.random.default_rng(seed)
    uavs = np.zeros((batch, n, 5))
    uavs[..., :2] = rng.uniform(0, spread, size=(batch, n, 2))
    uavs[..., 2] = rng.choice([400.0, 402.0, 405.0, 425.0], size=(batch, n))
    alive = rng.random((batch, n)) < 0.8
    expected = brute_force(uavs, alive, 5.0, reach)
    for form in ("dense", "edges"):
        found = as_dict(close_pairs(uavs, alive, 5.0, reach, form))
        assert found.keys() == expected.keys(), form
        assert all(found[k] == pytest.approx(expected[k], rel=1e-12) for k in expected)


def test_losses_closest_approach_and_time_in_conflict_of_a_set_course():
    # UAV 0 and 1 in one band close in and part: 30, 20, 8, 4, 12 m apart; UAV 2 flies
    # 2 m from UAV 0 but 10 m higher (another band); UAV 3 passes 1 m from UAV 1 and is dead
    gaps = [30.0, 20.0, 8.0, 4.0, 12.0]
    tally = Separation(batch=1, minimum=10.0, vertical=5.0, reach=50.0, dt=0.5)
    for gap in gaps:
        uavs = np.zeros((1, 4, 5))
        uavs[0, :, 2] = [425.0, 425.0, 435.0, 425.0]
        uavs[0, 1, 0] = gap
        uavs[0, 2, 1] = 2.0
        uavs[0, 3, :2] = [gap, 1.0]
        tally.add(uavs, np.array([[True, True, True, False]]))
    out = tally.summary()
    assert out["separation_losses"][0] == 2  # the steps at 8 and 4 m
    assert out["separation_min"][0] == 4.0
    assert out["conflict_time"][0] == 2 * 0.5


def test_no_minimum_counts_no_loss_but_still_the_closest_approach():
    tally = Separation(batch=2, minimum=0.0, vertical=5.0, reach=50.0, dt=0.5)
    uavs = np.zeros((2, 2, 5))
    uavs[:, :, 2] = [[425.0, 425.0], [425.0, 440.0]]  # trial 1: two bands
    uavs[:, 1, 0] = 3.0
    tally.add(uavs, np.ones((2, 2), dtype=bool))
    out = tally.summary()
    assert out["separation_losses"].tolist() == [0.0, 0.0]
    assert out["separation_min"][0] == 3.0 and np.isnan(out["separation_min"][1])
    assert out["conflict_time"].tolist() == [0.0, 0.0]


def test_a_run_reports_what_scipy_measures_on_its_trace():
    scenario = uavtrack.Scenario().with_overrides(
        {"uav.altitude_spacing": 0.0, "uav.separation": 10.0, "steps": 200}
    )
    result = uavtrack.simulate(scenario, seed=3)
    assert result.trace is not None
    uavs = result.trace.uavs  # (T, N, 5): every UAV alive, all at one altitude
    distances = np.stack([pdist(step[:, :2]) for step in uavs])  # (T, pairs)
    within = distances <= scenario.comm_range
    assert result.separation_min == pytest.approx(distances[within].min(), rel=1e-12)
    below = distances < 10.0
    assert result.separation_losses == below.sum() > 0
    assert result.conflict_time == pytest.approx(below.any(axis=1).sum() * scenario.dt)
    assert squareform(distances[0]).shape == (5, 5)


def test_the_paper_s_layered_team_never_shares_a_band():
    result = uavtrack.simulate(seed=0, trace=False)
    assert result.separation_losses == 0 and result.conflict_time == 0
    assert np.isnan(result.separation_min)


def test_the_command_line_reports_separation_and_refuses_a_negative_minimum(capsys):
    code = cli.main(["run", "--json", "--set", "steps=30", "--set", "uav.altitude_spacing=0"])
    out, _ = capsys.readouterr()
    shown = json.loads(out)
    assert code == 0 and shown["separation_losses"] == 0  # no minimum set
    assert 0 < shown["separation_min"] < uavtrack.Scenario().comm_range
    code = cli.main(["run", "--set", "uav.separation=-1"])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "uav.separation" in err
