"""The limits of an honest claim (`uavtrack.robust.plausibility`) and the rule of what a message
may hold (`uavtrack.agents.messages.Spec`): honest runs stay inside, the bounds are what
their mathematics says, and what breaks one is refused or not used, by reason."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import assignment, estimation, planning, sensing
from uavtrack.agents.messages import VERSION, Array, Part, Radio, Spec
from uavtrack.robust.plausibility import Bounds, best_accuracy, covariance_floor

SCENARIOS = [
    {},
    {"faults.loss": 0.3, "faults.delay": 2, "robust.stale": True},
    {"faults.position_std": 10.0},
    {"tracker.model": "imm", "target.motion": "manoeuvring"},
    {"target.noise_form": "printed"},
    {"fusion.rule": "covariance_intersection", "faults.loss": 0.2},
]


@pytest.mark.parametrize("overrides", SCENARIOS, ids=lambda o: ",".join(o) or "default")
def test_honest_runs_stay_within_the_bounds(overrides):
    scenario = uavtrack.Scenario(steps=300).with_overrides(overrides)
    b = Bounds.of(scenario)
    for method in ("distributed", "centralized"):
        trace = uavtrack.simulate(scenario, method, seed=2).trace
        mean, cov = trace.mean, trace.cov
        eig = np.linalg.eigvalsh(cov)
        assert eig[..., 0].min() >= b.floor and eig[..., -1].max() <= b.cap
        assert ((mean[..., :2] >= b.low) & (mean[..., :2] <= b.high)).all()
        assert np.hypot(mean[..., 2], mean[..., 3]).max() <= b.speed
        bids = trace.bids[np.isfinite(trace.bids)]
        assert bids.min() >= 0 and bids.max() <= b.bid
        uavs = trace.uavs
        assert ((uavs[..., :2] >= b.low) & (uavs[..., :2] <= b.high)).all()
        assert (uavs[..., 3] <= b.uav_speed).all()


def test_best_accuracy_bounds_every_converted_measurement(rng):
    scenario = uavtrack.Scenario()
    r_best = best_accuracy(scenario)
    h = np.asarray(scenario.altitudes())
    n = 20_000
    uav = np.zeros((n, 5))
    uav[:, 2] = rng.choice(h, n)
    d_edge = sensing.edge_range(uav[:, 2], scenario.sensor)
    d = rng.uniform(0.999 * uav[:, 2], d_edge)  # near the nadir (noise included) to the edge
    z = np.stack([d, rng.uniform(-np.pi, np.pi, n)], axis=-1)
    _, R = sensing.convert(uav, z, scenario.sensor)
    assert np.linalg.eigvalsh(R)[:, 0].min() >= r_best
    assert np.linalg.eigvalsh(R)[:, 0].min() < 10 * r_best  # and not far below the best


def test_the_floor_bounds_a_filter_fed_the_best_measurement_at_every_step(rng):
    # the recursion with R = r_best I is the lowest; any R >= r_best I stays above it
    scenario = uavtrack.Scenario(steps=300)
    floor = covariance_floor(scenario)
    r_best = best_accuracy(scenario)
    A = estimation.transition(scenario.dt)
    Q = estimation.process_noise(scenario.dt, *scenario.acceleration_std())
    e = scenario.estimation
    prior = np.diag([e.initial_position_std**2] * 2 + [e.initial_velocity_std**2] * 2)
    for best in (True, False):
        P, low = prior, np.inf
        for _ in range(scenario.steps):
            if best:
                R = r_best * np.eye(2)
            else:
                rot = np.linalg.qr(rng.normal(size=(2, 2)))[0]
                R = rot @ np.diag(r_best * (1 + rng.exponential(5, 2))) @ rot.T
            _, P = estimation.update(np.zeros(4), P, np.zeros(2), R)
            low = min(low, np.linalg.eigvalsh(P)[0])
            P = A @ P @ A.T + Q
        assert low >= floor
        if best:
            assert low == pytest.approx(2 * floor, rel=1e-9)  # the floor is half of it


def test_the_largest_bid_bounds_a_uav_right_above_its_target():
    scenario = uavtrack.Scenario()
    b = Bounds.of(scenario)
    h = scenario.altitudes()[0]
    uavs = np.array([[[100.0, 100.0, h, scenario.uav.speed, 0.3]]])
    mean = np.array([[[[100.0, 100.0, 0.0, 0.0], [110.0, 100.0, 1.0, 0.0]]]])
    p = planning.plan(uavs, mean, scenario.sensor, np.radians(45), 3, scenario.dt, 1.0, 9.81)
    assert np.nanmax(p.value) <= b.bid
    assert np.nanmax(p.value) >= b.bid / 8  # the bound is of the bid's order


# ------------------------------------------------------------------ the rule at the radio


def spec(**overrides):
    return Spec.of(uavtrack.Scenario().with_overrides(overrides), False)


def tuples(m=4, k=3):
    cov = np.broadcast_to(np.diag([4.0, 4.0, 1.0, 1.0]), (m, 4, 4)).copy()
    return {
        "gamma": 1.0 / np.trace(cov, axis1=-2, axis2=-1),
        "mean": np.tile([100.0, 100.0, 1.0, 0.0], (m, 1)),
        "cov": cov,
        "stamp": np.full(m, k),
        "origin": np.zeros(m, dtype=np.int64),
    }


def consensus(content, k=3, sender=1):
    wire = {name: Array.of(value) for name, value in content.items()}
    return Radio(
        version=VERSION, run="r", k=k, sender=sender, parts=[Part("consensus", 1, -1, wire)]
    )


def changed(name, fix):
    content = tuples()
    content[name] = fix(content[name].copy())
    return content


@pytest.mark.parametrize(
    "content,reason",
    [
        (changed("cov", lambda c: c * 0), "covariance not positive definite"),
        (changed("cov", lambda c: -c), "covariance not positive definite"),
        (
            changed("cov", lambda c: c + np.triu(np.ones((4, 4)), 1)),
            "covariance not positive definite",
        ),
        (changed("cov", lambda c: c * 1e300), "covariance beyond the run's largest"),
        (changed("gamma", lambda g: g * 1e300), "confidence disagrees with covariance"),
        (changed("gamma", lambda g: g * 0 - np.inf), "not finite"),
        (changed("mean", lambda x: x + np.nan), "not finite"),
        (changed("stamp", lambda s: s + 1), "stamp out of range"),
        (changed("origin", lambda o: o + 9), "index out of range"),
    ],
)
def test_a_tuple_no_honest_uav_sends_is_refused_by_reason(content, reason):
    s = spec()
    assert isinstance(s.radio(consensus(tuples()), 3), list)
    assert s.radio(consensus(content), 3) == reason


def test_a_tuple_beyond_the_plausibility_bounds_is_not_used_and_counted():
    s = spec()
    b = s.bounds
    content = tuples()
    content["mean"][0, :2] = b.high + 1.0  # outside the field plus the margin
    content["mean"][1, 2] = 2 * b.speed  # too fast
    content["cov"][2] = b.floor / 2 * np.eye(4)  # sharper than the sensor allows
    content["gamma"] = 1.0 / np.trace(content["cov"], axis1=-2, axis2=-1)
    parts = s.radio(consensus(content), 3)
    assert isinstance(parts, list)  # the message is admitted: the rest of it is used
    kept, reasons = s.estimates(parts[0][3])
    assert reasons == {
        "position out of bounds": 1,
        "speed out of bounds": 1,
        "covariance below the sensor's accuracy": 1,
    }
    assert np.isneginf(kept["gamma"][:3]).all() and np.isfinite(kept["gamma"][3])
    assert np.array_equal(kept["mean"][3], content["mean"][3])
    assert np.linalg.eigvalsh(kept["cov"])[:, 0].min() > 0  # safe to invert


def bids_message(bids, k=3):
    wire = {"bids": Array.of(np.asarray(bids, dtype=float)), "stamp": Array.of(np.array(k))}
    return Radio(version=VERSION, run="r", k=k, sender=1, parts=[Part("bids", 0, -1, wire)])


def test_bids_are_within_the_fisher_bound_and_nan_only_where_the_run_prunes():
    s = spec()
    top = s.bounds.bid
    assert isinstance(s.radio(bids_message([top, 0.0, np.nan, 1.0]), 3), list)
    assert s.radio(bids_message([top * 1.01, 0, 0, 0]), 3) == "bid out of bounds"
    assert s.radio(bids_message([-1.0, 0, 0, 0]), 3) == "bid out of bounds"
    assert s.radio(bids_message([np.nan] * 4), 3) == "bids not scored"
    lossy = spec(**{"faults.loss": 0.1})  # bids are never pruned where they may be lost
    assert lossy.radio(bids_message([1.0, np.nan, 1.0, 1.0]), 3) == "bids not scored"
    assert s.radio(bids_message([1.0] * 4, k=3), 4) != "stamp out of range"
    wrong = bids_message([1.0] * 4)
    wrong.parts[0].content["stamp"] = Array.of(np.array(2))
    assert s.radio(wrong, 3) == "stamp out of range"


# ------------------------------------------------------------------ the auction takes it


@st.composite
def auctions(draw):
    """A neighbourhood of n members whose honest ones score their k best bids (k the
    members of the largest neighbourhood they belong to, at least n), and liars that
    score fewer."""
    n = draw(st.integers(2, 6))
    m = draw(st.integers(1, 8))
    bids = np.array(draw(st.lists(st.floats(0, 10), min_size=n * m, max_size=n * m)))
    bids = bids.reshape(n, m)
    liars = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    liars[0] = False  # the receiver itself
    for row in range(n):
        keep = draw(st.integers(0, max(0, min(n, m) - 1))) if liars[row] else min(n, m)
        order = np.lexsort((np.arange(m), -bids[row]))
        bids[row, order[max(keep, 1 if liars[row] else keep) :]] = np.nan
    return bids, liars


@settings(max_examples=200, deadline=None)
@given(case=auctions())
def test_the_auction_takes_every_neighbourhood_the_rule_admits(case):
    bids, liars = case
    members = np.ones(len(bids), dtype=bool)
    able = assignment.able(bids, members, 0)
    assert able[0] and able[~liars].all()  # the receiver and every honest member
    rows = np.flatnonzero(able)
    target = assignment.local(bids[rows], 0)  # never raises
    assert 0 <= target < bids.shape[1]
