"""The measurement gate (`uavtrack.robust.gate`, ``robust.gate``): its test statistic, its
threshold, what it admits, and that the simulator and the agents run it alike."""

import numpy as np
import pytest
from scipy import stats

import uavtrack
from uavtrack.robust import gate


def test_the_threshold_is_the_chi_square_quantile_with_two_degrees_of_freedom():
    for p in (0.9, 0.99, 0.9999):
        assert gate.threshold(p) == pytest.approx(stats.chi2.ppf(p, 2), rel=1e-12)


def test_the_distance_is_the_innovation_mahalanobis_distance(rng):
    mean = rng.normal(size=(50, 4)) * 5
    a = rng.normal(size=(50, 4, 4))
    cov = a @ np.swapaxes(a, -1, -2) + np.eye(4)
    z = rng.normal(size=(50, 2)) * 5
    b = rng.normal(size=(50, 2, 2))
    R = b @ np.swapaxes(b, -1, -2) + 0.5 * np.eye(2)
    nu = z - mean[:, :2]
    S = cov[:, :2, :2] + R
    expected = np.einsum("ki,kij,kj->k", nu, np.linalg.inv(S), nu)
    assert np.allclose(gate.distance(mean, cov, z, R), expected, rtol=1e-10)


def test_honest_innovations_pass_the_gate_at_its_probability(rng):
    # z = H x + v with v ~ N(0, R) and x ~ N(mean, P): the statistic is chi-square(2)
    n = 200_000
    P = np.diag([4.0, 1.0, 0.5, 0.5])
    R = np.array([[2.0, 0.3], [0.3, 0.5]])
    truth = rng.multivariate_normal(np.zeros(4), P, size=n)
    z = truth[:, :2] + rng.multivariate_normal(np.zeros(2), R, size=n)
    d2 = gate.distance(
        np.zeros((n, 4)), np.broadcast_to(P, (n, 4, 4)), z, np.broadcast_to(R, (n, 2, 2))
    )
    for p in (0.9, 0.99):
        passed = (d2 <= gate.threshold(p)).mean()
        assert passed == pytest.approx(p, abs=5 * np.sqrt(p * (1 - p) / n))


def test_what_a_uav_measured_recently_and_the_initial_cue():
    observed = np.array([[[True, False, False]]])
    last = gate.seen(None, observed, 5)  # the cue of every target counts at step 0
    assert last.tolist() == [[[5, 0, 0]]]
    assert gate.recent(None, 3, 8, (1, 1, 3)).all() and not gate.recent(None, 9, 8, (1, 1, 3)).any()
    assert gate.recent(last, 9, 8, (1, 1, 3)).tolist() == [[[True, False, False]]]
    z, R = np.zeros((1, 2)), np.eye(2)[None]
    measured = gate.Measured.of(observed, z, R, gate.recent(last, 5, 8, (1, 1, 3)))
    assert measured.recent.tolist() == [[[False, True, True]]]  # not the one measured now


def test_a_sender_caught_on_one_target_is_believed_on_none_that_round():
    from uavtrack import network

    links = network.links(np.ones((1, 2, 2), dtype=bool), "dense")
    mine = np.zeros((1, 2, 2, 4))
    cov = np.broadcast_to(np.eye(4), (1, 2, 2, 4, 4))
    offered = mine.copy()
    offered[0, 1, 0, :2] = 100.0  # sender 1 lies about target 0 only
    observed = np.array([[[True, False], [False, False]]])  # receiver 0 measures target 0
    z = np.zeros((1, 2, 2, 2))
    R = np.broadcast_to(np.eye(2), (1, 2, 2, 2, 2))
    measured = gate.Measured(observed, z, R, np.zeros((1, 2, 2), dtype=bool))
    mask = gate.admitted(links, (mine, cov), (offered, cov), measured, gate.threshold(0.9999))
    assert mask[0, 0, 1].tolist() == [False, False]  # receiver 0 takes nothing from 1
    assert mask[0, 0, 0].tolist() == [True, True]  # its own stays
    assert mask[0, 1].all()  # receiver 1 measured nothing: everything


def test_the_gate_is_off_by_default_and_on_changes_the_paper_s_run():
    base = uavtrack.Scenario(steps=60)
    assert base.robust.gate is None
    off = uavtrack.simulate(base, "distributed", seed=3)
    on = uavtrack.simulate(base.with_overrides({"robust.gate": 0.9}), "distributed", seed=3)
    assert not np.array_equal(on.trace.mean, off.trace.mean)


# ------------------------------------------------------------------ with tracks


def tracks_scanned(z=(), recent=((False, False),), uav=(0.0, 0.0, 100.0, 0.0, 25.0)):
    """One receiver's scan for `gate.tracks_admitted`: measurements z (Z, 2) of noise I."""
    z = np.array(z, dtype=float).reshape(1, -1, 2)
    Z = z.shape[1]
    return gate.Scanned(
        z=z,
        R=np.broadcast_to(np.eye(2), (1, Z, 2, 2)).copy(),
        valid=np.ones((1, Z), dtype=bool),
        uav=np.array([uav]),
        recent=np.array(recent),
    )


def admitted_tracks(offers, slot, scanned, own=((0.0, 0.0),) * 2, sender=None):
    from uavtrack.config import Scenario

    mean = np.zeros((len(offers), 4))
    mean[:, :2] = offers
    cov = np.broadcast_to(np.eye(4), (len(offers), 4, 4))
    own_mean = np.zeros((len(own), 4))
    own_mean[:, :2] = own
    own_cov = np.broadcast_to(np.eye(4), (len(own), 4, 4))
    sender = np.ones(len(offers), dtype=np.int64) if sender is None else np.array(sender)
    row = np.zeros(len(offers), dtype=np.int64)
    return gate.tracks_admitted(
        row, sender, mean, cov, np.array(slot), (own_mean, own_cov), scanned,
        Scenario().sensor, gate.threshold(0.9999),
    )  # fmt: skip


def test_a_track_offered_for_a_recently_met_slot_must_agree_with_it():
    scanned = tracks_scanned(recent=((True, False),))
    near, far = (1.0, 1.0), (60.0, 0.0)
    assert admitted_tracks([near], [0], scanned).tolist() == [True]
    assert admitted_tracks([far], [0], scanned).tolist() == [False]
    # a slot not met recently checks nothing against its estimate
    assert admitted_tracks([far], [1], tracks_scanned(z=[far])).tolist() == [True]


def test_a_sender_caught_against_a_met_slot_is_believed_on_nothing_that_round():
    scanned = tracks_scanned(z=[(300.0, 0.0)], recent=((True, False),))
    offers = [(60.0, 0.0), (300.5, 0.0)]  # a lie about slot 0, then a true new track
    assert admitted_tracks(offers, [0, -1], scanned, sender=[1, 1]).tolist() == [False, False]
    assert admitted_tracks(offers, [0, -1], scanned, sender=[1, 2]).tolist() == [False, True]


def test_a_new_track_in_view_must_meet_a_measurement_and_one_out_of_view_passes():
    from uavtrack.config import Scenario
    from uavtrack.sensing import observation_radius

    reach = float(observation_radius(np.array(100.0), Scenario().sensor))
    inside, outside = (reach / 2, 0.0), (reach * 2, 0.0)
    seen = tracks_scanned(z=[(reach / 2 + 1.0, 0.0)])
    assert admitted_tracks([inside], [-1], seen).tolist() == [True]
    assert admitted_tracks([inside], [-1], tracks_scanned()).tolist() == [False]
    assert admitted_tracks([outside], [-1], tracks_scanned()).tolist() == [True]


def test_with_tracks_the_gate_changes_little_honest_at_a_wide_gate_for_every_method():
    base = uavtrack.Scenario(steps=30).with_overrides({"tracker.association": "jpda"})
    gated = base.with_overrides({"robust.gate": 0.9999})
    for method in ("distributed", "greedy", "centralized"):
        off = uavtrack.simulate(base, method, seed=2)
        on = uavtrack.simulate(gated, method, seed=2)
        assert on.observation_rate == pytest.approx(off.observation_rate, abs=0.05), method


def test_a_centralized_uav_keeps_its_own_copy_of_a_downloaded_slot_its_scan_refutes():
    from uavtrack.methods.base import Setting
    from uavtrack.methods.centralized import download_admitted
    from uavtrack.tracks import manage

    scenario = uavtrack.Scenario(tracker={"association": "jpda"}, robust={"gate": 0.9999})
    setting = Setting(
        faulty=False, delay=0, budget=None, extra_rounds=0, stale=False, forward=None,
        plan=None, gate=gate.threshold(0.9999), scenario=scenario,
    )  # fmt: skip
    K = 3
    book = manage.Book(
        label=np.arange(K)[None, None], status=np.array([[[2, 2, 1]]], dtype=np.int8),
        hits=np.zeros((1, 1, K), int), scans=np.zeros((1, 1, K), int),
        misses=np.zeros((1, 1, K), int), serial=np.zeros((1, 1), int),
        stamp=np.zeros((1, 1, K), int),
    )  # fmt: skip
    mean = np.zeros((1, 1, K, 4))
    mean[0, 0, :, 0] = [5.0, -5.0, -5.0]  # slot 0 where the UAV measured, 1 and 2 elsewhere
    cov = np.broadcast_to(np.eye(4), (1, 1, K, 4, 4))
    z = np.array([[[[5.0, 0.0]]]])
    scan = (z, np.broadcast_to(np.eye(2), (1, 1, 1, 2, 2)), np.ones((1, 1, 1), dtype=bool))
    uav = np.array([[[0.0, 0.0, 100.0, 0.0, 25.0]]])  # its view: a disk of 8.7 m
    ok = download_admitted(book, mean, cov, scan, uav, setting)
    # slot 0 agrees with the measurement; slot 1 is refuted; slot 2 is tentative: no claim
    assert ok.tolist() == [[[True, False, True]]]
