"""Track existence (integrated PDA, JIPDA) and the merging of tracks that hold one target
(``tracker.confirmation = "existence"``, ``tracker.merge``; `tracks.manage`)."""

import numpy as np
import pytest

import uavtrack
from uavtrack.tracks import association, manage
from uavtrack.tracks.manage import CONFIRMED, EMPTY, TENTATIVE

SENSOR = {"sensor.detection_probability": 0.9, "sensor.clutter_rate": 2.0}


def _scenario(**tracker):
    return uavtrack.Scenario(
        n_uavs=1,
        n_targets=1,
        tracker={"association": "jpda", "confirmation": "existence", **tracker},
    ).with_overrides(SENSOR)


def _track(x=0.0, y=0.0, std=1.0):
    mean = np.array([[[[x, y, 0.0, 0.0]]]])
    return mean, np.broadcast_to(np.eye(4) * std**2, (1, 1, 1, 4, 4)).copy()


def _lone_scans(seed: int, count: int = 50):
    """Random scans of a track alone in its cluster: (innovations, gated, r, P_D, lambda)."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        mean, cov = _track(std=rng.uniform(0.5, 5))
        Z = int(rng.integers(0, 4))
        z = rng.normal(0, 4, (1, Z, 2))
        R = np.broadcast_to(np.eye(2) * rng.uniform(0.5, 3), (1, Z, 2, 2)).copy()
        inn = association.innovations(mean[0], cov[0], z, R)
        gated = association.gate(inn.d2, np.ones((1, 1), bool), np.ones((1, Z), bool), 0.99)
        r = np.array([[rng.uniform(0.01, 0.99)]])
        yield inn, gated, r, np.array([[0.9]]), np.array([rng.uniform(1e-4, 1e-2)])


def test_ipda_and_jipda_agree_on_a_track_alone():
    """A track alone in its cluster: the JIPDA form over the association's weights (with
    P_D r in them) is the integrated PDA's closed form, for any scan."""
    for inn, gated, r, pd, density in _lone_scans(1):
        beta = association.jpda(inn, gated, pd * r, density, 0.99)
        ipda = manage.existence_update(r, inn, gated, pd, density, 0.99)
        jipda = manage.existence_update(r, inn, gated, pd, density, 0.99, beta)
        np.testing.assert_allclose(jipda, ipda, rtol=1e-9)


def test_given_existence_a_lone_tracks_weights_are_pdas_with_p_d():
    """JIPDA's weights (with P_D r) conditioned on existence are, for a track alone in
    its cluster, PDA's weights with P_D: whether it exists does not change which
    measurement it would have made."""
    for inn, gated, r, pd, density in _lone_scans(3):
        jipda = association.jpda(inn, gated, pd * r, density, 0.99)
        given = manage.given_existence(jipda, r, pd, 0.99)
        pda = association.jpda(inn, gated, pd, density, 0.99)
        np.testing.assert_allclose(given, pda, rtol=1e-9)
        np.testing.assert_allclose(given.sum(axis=-1), 1.0)


def test_a_miss_multiplies_the_odds_by_one_minus_pd_pg_and_unseen_tracks_keep_theirs():
    mean, cov = _track()
    z, R = np.zeros((1, 0, 2)), np.zeros((1, 0, 2, 2))
    inn = association.innovations(mean[0], cov[0], z, R)
    gated = np.zeros((1, 1, 0), bool)
    r = np.array([[0.6]])
    after = manage.existence_update(r, inn, gated, np.array([[0.9]]), np.array([1e-3]), 0.99)
    odds = lambda p: p / (1 - p)  # noqa: E731
    assert odds(after[0, 0]) == pytest.approx(odds(0.6) * (1 - 0.9 * 0.99))
    unseen = manage.existence_update(r, inn, gated, np.array([[0.0]]), np.array([1e-3]), 0.99)
    assert unseen[0, 0] == pytest.approx(0.6)


def test_existence_confirms_a_target_fast_and_lets_clutter_die():
    """A track born on a target measured near its centre is confirmed two scans after its
    birth (the M-of-N rule's 4 of 5 takes three); one born on clutter that nothing meets
    again is deleted at the next scan in view."""
    scenario = _scenario()
    K = scenario.track_slots
    book, mean, cov = manage.briefed(np.zeros((1, 1, 0, 4)), np.zeros((1, 1, 0, 4, 4)), K)
    c = scenario.field_size / 2
    uav = np.array([[[c, c, scenario.uav.altitude, 0.0, 0.0]]])
    R = np.broadcast_to(np.eye(2) * 4.0, (1, 1, 2, 2, 2)).copy()
    target, clutter = np.array([c + 5, c]), np.array([c - 20, c + 10])
    statuses = []
    for k in range(6):
        z = np.stack([target + 0.5 * np.sin(k), clutter if k == 0 else target + 30])[None, None]
        valid = np.array([[[True, k == 0]]])
        s = manage.scan(book, mean, cov, z, R, valid, uav, np.ones((1, 1), bool), scenario, k=k)
        book, mean, cov = s.book, s.mean, s.cov
        statuses.append(book.status[0, 0].copy())
    on_target = np.argmin(np.linalg.norm(mean[0, 0, :, :2] - target, axis=-1))
    assert statuses[1][on_target] == TENTATIVE and statuses[2][on_target] == CONFIRMED
    assert (statuses[0] == TENTATIVE).sum() == 2 and (statuses[1] != EMPTY).sum() == 1
    assert (book.status[0, 0] == CONFIRMED).sum() == 1


def test_existence_without_clutter_reaches_its_cap_and_no_further():
    """No clutter (a density at the smallest float): a detection makes L overflow, and
    the update must still give a number, the cap; a track that does not exist stays so."""
    mean, cov = _track()
    z, R = np.zeros((1, 1, 2)), np.eye(2)[None, None]
    inn = association.innovations(mean[0], cov[0], z, R)
    gated = np.ones((1, 1, 1), bool)
    tiny = np.array([np.finfo(float).tiny])
    for r in (0.0, 0.3, 0.999):
        after = manage.existence_update(np.array([[r]]), inn, gated, np.array([[1.0]]), tiny, 0.99)
        assert np.isfinite(after).all()
        assert after[0, 0] == (manage.EXISTENCE_CAP if r > 0 else 0.0)


def _two_tracks(offset, std_b):
    """One row with two confirmed tracks: a sure one at 0 and another `offset` m east."""
    mean = np.zeros((1, 1, 3, 4))
    mean[0, 0, 1, 0] = offset
    cov = np.broadcast_to(np.eye(4), (1, 1, 3, 4, 4)).copy()
    cov[0, 0, 0] *= 0.3**2
    cov[0, 0, 1] *= std_b**2
    book = manage.Book(
        label=np.array([[[40, 7, -1]]]),
        status=np.array([[[CONFIRMED, CONFIRMED, EMPTY]]], np.int8),
        hits=np.zeros((1, 1, 3), np.int64),
        scans=np.zeros((1, 1, 3), np.int64),
        misses=np.zeros((1, 1, 3), np.int64),
        serial=np.zeros((1, 1), np.int64),
        stamp=np.array([[[5, 3, 0]]]),
        existence=np.array([[[0.9, 0.8, 0.0]]]),
    )
    return book, mean, cov


def test_two_tracks_of_one_target_merge_after_the_window_under_the_smaller_label():
    settings = _scenario(merge=3).tracker
    book, mean, cov = _two_tracks(offset=8.0, std_b=5.0)  # d2 = 64 / 25.09 < 9.21
    view = np.array([[[True, True, False]]])
    for scan in range(3):
        assert (book.status[0, 0, :2] == CONFIRMED).all(), scan
        book = manage.merge(book, mean, cov, view if scan != 1 else view, settings)
    assert book.status[0, 0, 1] == EMPTY and book.label[0, 0, 1] == -1
    assert book.status[0, 0, 0] == CONFIRMED
    assert book.label[0, 0, 0] == 7 and book.stamp[0, 0, 0] == 5  # the smaller label, newest stamp
    assert book.existence[0, 0, 0] == 0.9 and book.close[0, 0, 0] == 0


def test_a_scan_out_of_view_neither_counts_nor_breaks_the_window():
    settings = _scenario(merge=2).tracker
    book, mean, cov = _two_tracks(offset=8.0, std_b=5.0)
    view, away = np.array([[[True, True, False]]]), np.zeros((1, 1, 3), bool)
    book = manage.merge(book, mean, cov, view, settings)
    book = manage.merge(book, mean, cov, away, settings)
    assert book.close[0, 0, 0] == 1 and (book.status[0, 0, :2] == CONFIRMED).all()
    book = manage.merge(book, mean, cov, view, settings)
    assert book.status[0, 0, 1] == EMPTY


def test_two_sure_tracks_a_few_metres_apart_never_merge():
    """Two targets crossing: sure tracks (std 0.3 m) 3 m apart lie far outside each
    other's gate (d2 = 50), whatever the window."""
    settings = _scenario(merge=1).tracker
    book, mean, cov = _two_tracks(offset=3.0, std_b=0.3)
    view = np.array([[[True, True, False]]])
    for _ in range(20):
        book = manage.merge(book, mean, cov, view, settings)
    assert (book.status[0, 0, :2] == CONFIRMED).all() and (book.close[0, 0, :2] == 0).all()


def test_existence_settings_need_existence_and_thresholds_in_order():
    with pytest.raises(ValueError, match="tracker.confirmation = existence"):
        uavtrack.Scenario(
            tracker={"association": "jpda", "confirmation": "m_of_n", "survival": 0.9}
        )
    with pytest.raises(ValueError, match="delete < birth_existence < confirm"):
        uavtrack.Scenario(
            tracker={"association": "jpda", "confirmation": "existence", "existence": (0.5, 0.2),
                     "birth_existence": 0.6}
        )  # fmt: skip
    with pytest.raises(ValueError, match="tracker.association=gnn"):
        uavtrack.Scenario(tracker={"merge": 3})
