"""A UAV's track slots: start, M-of-N confirmation, deletion, births (`tracks.manage`)."""

import numpy as np
import pytest

import uavtrack
from uavtrack.tracks import manage
from uavtrack.tracks.manage import CONFIRMED, EMPTY, TENTATIVE


def _scenario(**tracker):
    return uavtrack.Scenario(
        n_uavs=1, n_targets=1, tracker={"association": "gnn", "confirmation": "m_of_n", **tracker}
    )


def _one(status, hits=0, scans=0, misses=0, label=7):
    """A book of one UAV with one slot."""
    a = lambda v, t=np.int64: np.array([[[v]]], dtype=t)  # noqa: E731
    return manage.Book(
        label=a(label),
        status=a(status, np.int8),
        hits=a(hits),
        scans=a(scans),
        misses=a(misses),
        serial=np.zeros((1, 1), dtype=np.int64),
        stamp=a(0),
    )


def _cov(std=1.0):
    return np.broadcast_to(np.eye(4) * std**2, (1, 1, 1, 4, 4)).copy()


def test_the_briefing_is_every_target_confirmed_under_its_index():
    mean = np.random.default_rng(0).normal(size=(2, 3, 4, 4))
    cov = np.broadcast_to(np.eye(4), (2, 3, 4, 4, 4)).copy()
    book, m, c = manage.briefed(mean, cov, 6)
    assert m.shape == (2, 3, 6, 4) and c.shape == (2, 3, 6, 4, 4)
    np.testing.assert_array_equal(m[:, :, :4], mean)
    assert (book.label[:, :, :4] == np.arange(4)).all() and (book.label[:, :, 4:] == -1).all()
    assert (book.status[:, :, :4] == CONFIRMED).all() and (book.status[:, :, 4:] == EMPTY).all()
    with pytest.raises(ValueError, match="cannot hold"):
        manage.briefed(mean, cov, 3)


def test_without_a_briefing_the_mission_starts_with_no_track_and_finds_the_targets():
    mean = np.random.default_rng(0).normal(size=(2, 3, 4, 4))
    cov = np.broadcast_to(np.eye(4), (2, 3, 4, 4, 4)).copy()
    book, m, c = manage.briefed(mean, cov, 6, briefing=False)
    assert not book.present.any() and m.shape == (2, 3, 6, 4)
    scenario = uavtrack.Scenario(steps=80).with_overrides(
        {"tracker.association": "jpda", "tracker.briefing": False}
    )
    r = uavtrack.simulate(scenario, seed=1, trace=True)
    label, status = r.trace.label, r.trace.status
    assert not ((label >= 0) & (label < scenario.n_targets)).any()  # no briefed label
    assert (status[-1] == CONFIRMED).any() and r.siap_completeness > 0.25  # found some


@pytest.mark.parametrize(
    ("history", "outcome"),
    [
        ([True], CONFIRMED),  # born (1 hit) + 1 = 2 of 2 scans
        ([False, True], CONFIRMED),  # 2 of 3
        ([False, False], EMPTY),  # 1 of 3: can no longer reach 2
    ],
)
def test_two_of_three_confirms_or_deletes(history, outcome):
    scenario = _scenario(confirm=(2, 3))
    book = _one(TENTATIVE, hits=1, scans=1)  # a track just born: its first scan met
    view = np.ones((1, 1, 1), dtype=bool)
    for met in history:
        book = manage._count(book, np.array([[[met]]]), view, _cov(), scenario)
    assert book.status[0, 0, 0] == outcome
    assert (book.label[0, 0, 0] == -1) == (outcome == EMPTY)


def test_a_tentative_track_out_of_view_waits():
    book = _one(TENTATIVE, hits=1, scans=1)
    for _ in range(10):
        none = np.zeros((1, 1, 1), bool)
        book = manage._count(book, none, none, _cov(), _scenario())
    assert book.status[0, 0, 0] == TENTATIVE and book.scans[0, 0, 0] == 1


def test_a_confirmed_track_dies_after_its_misses_in_view_only():
    scenario = _scenario(delete_misses=3)
    book = _one(CONFIRMED)
    miss, view, away = (
        np.zeros((1, 1, 1), bool),
        np.ones((1, 1, 1), bool),
        np.zeros((1, 1, 1), bool),
    )
    book = manage._count(book, miss, view, _cov(), scenario)
    book = manage._count(book, miss, away, _cov(), scenario)  # out of view: not a miss
    book = manage._count(book, miss, view, _cov(), scenario)
    assert book.status[0, 0, 0] == CONFIRMED and book.misses[0, 0, 0] == 2
    hit = np.ones((1, 1, 1), bool)
    book = manage._count(book, hit, view, _cov(), scenario)  # a hit resets the count
    assert book.misses[0, 0, 0] == 0
    for _ in range(3):
        book = manage._count(book, miss, view, _cov(), scenario)
    assert book.status[0, 0, 0] == EMPTY


def test_a_track_whose_position_spreads_too_far_is_deleted():
    scenario = _scenario(delete_std=50.0)
    none = np.zeros((1, 1, 1), bool)
    kept = manage._count(_one(CONFIRMED), none, none, _cov(35.0), scenario)  # sqrt(2) 35 < 50
    gone = manage._count(_one(CONFIRMED), none, none, _cov(36.0), scenario)  # 50.9 > 50
    assert kept.status[0, 0, 0] == CONFIRMED and gone.status[0, 0, 0] == EMPTY


def test_births_fill_empty_slots_with_labels_new_to_the_team():
    B, N, K, Z = 1, 3, 3, 4
    book = manage.Book(
        label=np.array([[[0, -1, -1], [0, 1, 2], [-1, -1, -1]]]),
        status=np.array([[[2, 0, 0], [2, 2, 2], [0, 0, 0]]], dtype=np.int8),
        hits=np.zeros((B, N, K), np.int64),
        scans=np.zeros((B, N, K), np.int64),
        misses=np.zeros((B, N, K), np.int64),
        serial=np.array([[0, 0, 5]]),
        stamp=np.zeros((B, N, K), np.int64),
    )
    mean = np.zeros((B, N, K, 4))
    cov = np.broadcast_to(np.eye(4), (B, N, K, 4, 4)).copy()
    z = np.arange(B * N * Z * 2, dtype=float).reshape(B * N, Z, 2)
    R = np.broadcast_to(np.eye(2) * 3.0, (B * N, Z, 2, 2)).copy()
    unused = np.array(
        [[True, False, True, True], [True, False, False, False], [False, True, True, False]]
    )
    out, m, c, born = manage._births(book, mean, cov, z, R, unused, 4, 2.0, (0, N))
    # UAV 0: 3 unused, 2 empty slots -> the first two unused measurements are born
    assert born[0, 0].tolist() == [False, True, True]
    np.testing.assert_array_equal(m[0, 0, 1, :2], z[0, 0]) and np.testing.assert_array_equal(
        m[0, 0, 2, :2], z[0, 2]
    )
    assert (m[0, 0, 1:, 2:] == 0).all() and c[0, 0, 1, 2, 2] == 4.0 and c[0, 0, 1, 0, 0] == 3.0
    assert not born[0, 1].any()  # UAV 1: no room
    assert born[0, 2].tolist() == [True, True, False]
    assert (out.status[born] == TENTATIVE).all() and (out.hits[born] == 1).all()
    # labels: n_targets + serial * N + uav, each new to the team
    assert out.label[0, 0, 1:].tolist() == [4 + 0 * 3 + 0, 4 + 1 * 3 + 0]
    assert out.label[0, 2, :2].tolist() == [4 + 5 * 3 + 2, 4 + 6 * 3 + 2]
    assert out.serial.tolist() == [[2, 0, 7]]
    # a UAV's program runs its row alone (team: its index, the team's size): the same labels
    row = manage.Book(**{f: getattr(book, f)[:, 2:] for f in book.__dataclass_fields__})
    alone = manage._births(row, mean[:, 2:], cov[:, 2:], z[2:], R[2:], unused[2:], 4, 2.0, (2, N))
    assert alone[0].label[0, 0].tolist() == out.label[0, 2].tolist()
    np.testing.assert_allclose(alone[1][0, 0], m[0, 2], rtol=1e-15)
