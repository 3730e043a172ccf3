"""The team's agreement on tracks: association of neighbours' tracks, fusion, adoption and
team labels (`uavtrack.tracks.team`)."""

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from uavtrack import faults, fusion, network
from uavtrack.config import FaultModel
from uavtrack.estimation import confidence
from uavtrack.radio import Radio, RadioState
from uavtrack.tracks import team
from uavtrack.tracks.team import TrackSet

GATE = float(chi2.ppf(0.99, 4))


def empty(B, n, K):
    return TrackSet(
        mean=np.zeros((B, n, K, 4)),
        cov=np.broadcast_to(np.eye(4), (B, n, K, 4, 4)).copy(),
        label=np.full((B, n, K), -1, dtype=np.int64),
        status=np.zeros((B, n, K), dtype=np.int8),
    )


def put(tracks, b, i, k, mean, cov, label, status=team.CONFIRMED):
    tracks.mean[b, i, k], tracks.cov[b, i, k] = mean, cov
    tracks.label[b, i, k], tracks.status[b, i, k] = label, status


def spd(rng, scale=1.0):
    L = rng.normal(size=(4, 4)) * scale
    return L @ L.T + 0.5 * scale**2 * np.eye(4)


def dense(matrix):
    """Links [trial, receiver, sender] with self-links, as the radio delivers them."""
    matrix = np.asarray(matrix, dtype=bool)
    n = matrix.shape[-1]
    return network.Links(batch=matrix.shape[0], n=n, dense=matrix | np.eye(n, dtype=bool))


def lossy(adjacency, loss, form="auto"):
    B, n = adjacency.shape[:2]
    keys = np.stack([faults.trial_key(np.random.SeedSequence(50 + b)) for b in range(B)])
    realisation = faults.Faults(FaultModel(loss=loss), keys, n)
    alive = np.ones((B, n), dtype=bool)
    return Radio(0, network.links(adjacency, form), alive, realisation, RadioState()), realisation


def connected_graph(rng, n, extra):
    adj = np.zeros((n, n), dtype=bool)
    for k in range(1, n):  # a random spanning tree, then some chords
        j = rng.integers(k)
        adj[k, j] = adj[j, k] = True
    for _ in range(extra):
        a, b = rng.integers(n, size=2)
        if a != b:
            adj[a, b] = adj[b, a] = True
    return adj


def held_targets(tracks, truth, b, i):
    """The target nearest to each confirmed track of UAV i, with its label and slot."""
    out = []
    for k in np.flatnonzero(tracks.status[b, i] == team.CONFIRMED):
        j = int(np.argmin(np.linalg.norm(truth[:, :2] - tracks.mean[b, i, k, :2], axis=1)))
        out.append((j, int(tracks.label[b, i, k]), int(k)))
    return out


# ------------------------------------------------------------------ the team converges


@st.composite
def teams(draw):
    n = draw(st.integers(2, 8))
    m = draw(st.integers(1, 4))
    extra = draw(st.integers(0, 2))
    seed = draw(st.integers(0, 2**32 - 1))
    form = draw(st.sampled_from(["dense", "edges"]))
    return n, m, extra, seed, form


@settings(max_examples=60, deadline=None)
@given(case=teams())
def test_every_uav_ends_with_every_target_under_the_smallest_label(case):
    n, m, extra, seed, form = case
    rng = np.random.default_rng(seed)
    adj = connected_graph(rng, n, rng.integers(0, 2 * n))
    K = m + extra
    truth = np.zeros((m, 4))
    truth[:, 0] = 1000.0 * np.arange(m)  # well separated targets
    truth[:, 2:] = rng.normal(size=(m, 2))
    holds = rng.random((n, m)) < 0.5
    holds[rng.integers(n, size=m), np.arange(m)] = True  # every target held by someone
    labels = rng.choice(10**6, size=(n, m), replace=False)
    tracks = empty(1, n, K)
    initial = {}
    for i in range(n):
        slots = rng.permutation(K)
        for j in np.flatnonzero(holds[i]):
            P = spd(rng, scale=rng.uniform(0.5, 3.0))
            # a small bounded error: e^T P^-1 e <= 0.16, far inside the gate
            error = np.linalg.cholesky(P) @ rng.uniform(-0.2, 0.2, size=4)
            put(tracks, 0, i, slots[j], truth[j] + error, P, labels[i, j])
            initial[i, j] = (truth[j] + error, P)
    diameter = nx.diameter(nx.from_numpy_array(adj.astype(int)))
    radio = fusion.perfect_radio(adj[None], form)
    rounds = np.full((1, n), diameter)
    agreed = team.agree(radio, tracks, rounds, GATE)
    out, changed = agreed.tracks, agreed.changed

    for j in range(m):
        holders = np.flatnonzero(holds[:, j])
        team_label = labels[holders, j].min()
        # the most confident of the UAVs' estimates of j (max-consensus over the team)
        best = max(holders, key=lambda i, j=j: confidence(initial[i, j][1]))
        for i in range(n):
            found = [
                (label, k) for target, label, k in held_targets(out, truth, 0, i) if target == j
            ]
            assert len(found) == 1  # held, and held once
            label, k = found[0]
            assert label == team_label
            assert np.allclose(out.mean[0, i, k], initial[best, j][0], rtol=1e-12, atol=1e-9)
            assert np.allclose(out.cov[0, i, k], initial[best, j][1], rtol=1e-12, atol=1e-12)
            if not holds[i, j]:
                assert changed[0, i, k] == team.ADOPTED
            elif best == i and label == labels[i, j]:
                assert changed[0, i, k] == team.KEPT
            else:
                assert changed[0, i, k] == team.FUSED
    for i in range(n):
        present = out.label[0, i][out.status[0, i] > 0]
        assert present.size == m and np.unique(present).size == m  # unique labels
        assert (out.label[0, i][out.status[0, i] == 0] == -1).all()


def test_thirty_uavs_in_the_edge_form_agree_as_in_the_dense_form():
    rng = np.random.default_rng(3)
    n, m, K, B = 30, 3, 5, 2
    uavs = np.zeros((B, n, 5))
    uavs[:, :, 0] = np.arange(n) * 40.0  # a path of 30 UAVs, 40 m apart, r_C 50 m
    adj = network.adjacency(uavs, 50.0)
    truth = np.zeros((m, 4))
    truth[:, 0] = 1000.0 * np.arange(m)
    tracks = empty(B, n, K)
    labels = rng.choice(10**6, size=(B, n, m), replace=False)
    holds = rng.random((B, n, m)) < 0.3
    holds[:, 0] = True
    for b in range(B):
        for i in range(n):
            for j in np.flatnonzero(holds[b, i]):
                P = spd(rng)
                error = np.linalg.cholesky(P) @ rng.uniform(-0.2, 0.2, size=4)
                put(tracks, b, i, j + 1, truth[j] + error, P, labels[b, i, j])
    rounds = np.full((B, n), n - 1)  # the path's diameter
    edges = fusion.perfect_radio(adj, "auto")
    assert edges.now.links.edges
    agreed = team.agree(edges, tracks, rounds, GATE)
    out, changed, sent, delivered = agreed.tracks, agreed.changed, agreed.sent, agreed.delivered
    agreed = team.agree(fusion.perfect_radio(adj, "dense"), tracks, rounds, GATE)
    ref, ref_changed, ref_sent, ref_delivered = (
        agreed.tracks,
        agreed.changed,
        agreed.sent,
        agreed.delivered,
    )
    assert np.array_equal(out.label, ref.label) and np.array_equal(out.status, ref.status)
    assert np.array_equal(changed, ref_changed)
    assert np.allclose(out.mean, ref.mean, rtol=1e-12, atol=1e-9)
    assert np.array_equal(sent, ref_sent) and np.array_equal(delivered, ref_delivered)
    for b in range(B):
        smallest = np.where(holds[b], labels[b], np.iinfo(np.int64).max).min(axis=0)
        for i in range(n):
            got = sorted((j, label) for j, label, _ in held_targets(out, truth, b, i))
            assert got == [(j, smallest[j]) for j in range(m)]


# ------------------------------------------------------------------ the fusion rules


@pytest.mark.parametrize("form", ["dense", "edges"])
@pytest.mark.parametrize("depth", [True, False])
def test_with_known_labels_max_consensus_equals_the_per_target_consensus(form, depth):
    rng = np.random.default_rng(7)
    B, n, m = 4, 7, 3
    adj = np.stack([connected_graph(rng, n, 3) for _ in range(B)])
    adj[1] = False  # and a team without links: every UAV keeps its own
    adj[1, 0, 1] = adj[1, 1, 0] = True
    tracks = empty(B, n, m)
    for b in range(B):
        for i in range(n):
            for j in range(m):  # every UAV holds every target in slot j under label 100 j
                put(tracks, b, i, j, rng.normal(size=4) * 3, spd(rng, rng.uniform(0.3, 3)), 100 * j)
    if depth:  # D_i, or any rounds: a UAV past its rounds keeps its tracks
        rounds = fusion.learn_depth(fusion.perfect_radio(adj, form), np.ones((B, n), bool)).depth
    else:
        rounds = rng.integers(0, 3, size=(B, n))
    agreed = team.agree(fusion.perfect_radio(adj, form), tracks, rounds, GATE)
    out, changed, sent, delivered = agreed.tracks, agreed.changed, agreed.sent, agreed.delivered

    gamma = confidence(tracks.cov)
    oracle = fusion.consensus(
        fusion.perfect_radio(adj, form),
        fusion.Estimates(gamma=gamma, source=fusion.identity(gamma.shape)),
        rounds,
    )
    source = oracle.tuples.source
    assert np.allclose(out.mean, fusion.gather(source, tracks.mean), rtol=1e-12, atol=1e-12)
    assert np.allclose(out.cov, fusion.gather(source, tracks.cov), rtol=1e-12, atol=1e-12)
    assert np.array_equal(out.label, tracks.label)
    own = source == np.arange(n)[:, None]
    assert np.array_equal(changed, np.where(own, team.KEPT, team.FUSED))
    assert (~own).any() and own.any()
    assert np.array_equal(sent, oracle.sent) and np.array_equal(delivered, oracle.delivered)


def test_a_matched_pair_fuses_as_covariance_intersection_does(rng):
    a, b, c = np.array([10.0, 5, 1, 0]), np.array([10.5, 4.5, 1.2, 0.1]), np.array([9.8, 5, 1, 0])
    A, Bc, C = spd(rng, 1.0), spd(rng, 1.5), spd(rng, 0.8)
    # step 3: UAV 0 (label 9) and UAV 1 (label 4) hold one target under different labels
    tracks = empty(1, 2, 2)
    put(tracks, 0, 0, 1, a, A, 9)
    put(tracks, 0, 1, 0, b, Bc, 4)
    links = dense(np.ones((1, 2, 2)))
    out, changed = team.team_round(tracks, tracks, links, GATE, "covariance_intersection")
    own = fusion.Estimates(mean=np.array([[[a], [b]]]), cov=np.array([[[A], [Bc]]]))
    ci = fusion.intersect_round(own, own, links)
    assert np.allclose(out.cov[0, 0, 1], ci.cov[0, 0, 0], rtol=1e-9, atol=1e-12)
    assert np.allclose(out.mean[0, 0, 1], ci.mean[0, 0, 0], rtol=1e-9, atol=1e-9)
    assert np.allclose(out.cov[0, 1, 0], ci.cov[0, 1, 0], rtol=1e-9, atol=1e-12)
    assert out.label[0, 0, 1] == out.label[0, 1, 0] == 4
    assert changed[0, 0, 1] == changed[0, 1, 0] == team.FUSED
    assert changed[0, 0, 0] == changed[0, 1, 1] == team.KEPT

    # step 2: three UAVs hold it under one label, UAV 0 fuses its own and two offers
    tracks = empty(1, 3, 1)
    for i, (x, P) in enumerate(((a, A), (b, Bc), (c, C))):
        put(tracks, 0, i, 0, x, P, 4)
    links = dense(np.ones((1, 3, 3)))
    out, _ = team.team_round(tracks, tracks, links, GATE, "covariance_intersection")
    own = fusion.Estimates(mean=tracks.mean, cov=tracks.cov)
    ci = fusion.intersect_round(own, own, links)
    assert np.allclose(out.cov, ci.cov, rtol=1e-9, atol=1e-12)
    assert np.allclose(out.mean, ci.mean, rtol=1e-9, atol=1e-9)


# ------------------------------------------------------------------ association


def pair(distance_squared):
    """UAV 0 (label 3) and UAV 1 (label 8) each hold a track, the two at d2 apart."""
    tracks = empty(1, 2, 3)
    P = np.diag([2.0, 2.0, 0.5, 0.5])
    x = np.array([0.0, 0.0, 1.0, 0.0])
    y = x + np.array([np.sqrt(distance_squared * 4.0), 0, 0, 0])  # (P_a + P_b)_00 = 4
    put(tracks, 0, 0, 0, x, P, 3)
    put(tracks, 0, 1, 2, y, P, 8)
    return tracks


def test_tracks_outside_the_gate_stay_apart_with_their_own_labels():
    tracks = pair(GATE * 1.01)
    radio = fusion.perfect_radio(network.complete(2, (1,)))
    agreed = team.agree(radio, tracks, np.ones((1, 2), dtype=int), GATE)
    out, changed = agreed.tracks, agreed.changed
    for i in range(2):  # each keeps its own and adopts the other's, separate
        assert sorted(out.label[0, i][out.status[0, i] > 0].tolist()) == [3, 8]
    assert changed[0, 0].tolist() == [team.KEPT, team.ADOPTED, team.KEPT]

    tracks = pair(GATE * 0.99)
    radio = fusion.perfect_radio(network.complete(2, (1,)))
    agreed = team.agree(radio, tracks, np.ones((1, 2), dtype=int), GATE)
    out, changed = agreed.tracks, agreed.changed
    for i in range(2):  # inside the gate: one track, the smaller label
        assert out.label[0, i][out.status[0, i] > 0].tolist() == [3]
    assert changed[0, 1].tolist() == [team.KEPT, team.KEPT, team.FUSED]


def test_the_assignment_minimises_the_total_distance():
    # own tracks at x = 0 and 2, offers at 1.2 and 3.5 (P_a + P_b = 2 I: d2 = dx^2 / 2):
    # the nearest own track of the first offer is the one at 2, but the pairing of least
    # total d2 is (0, 1.2), (2, 3.5): 1.44 / 2 + 2.25 / 2 against 0.64 / 2 + 12.25 / 2
    tracks = empty(1, 2, 3)
    for k, (x, label) in enumerate(((0.0, 10), (2.0, 20))):
        put(tracks, 0, 0, k, np.array([x, 0, 0, 0]), np.eye(4), label)
    for k, (x, label) in enumerate(((1.2, 5), (3.5, 6))):
        put(tracks, 0, 1, k, np.array([x, 0, 0, 0]), np.eye(4) * (1 + 0.01 * k), label)
    links = dense([[[True, True], [False, True]]])  # UAV 0 hears UAV 1
    out, changed = team.team_round(tracks, tracks, links, GATE)
    assert out.label[0, 0].tolist() == [5, 6, -1]
    assert changed[0, 0].tolist() == [team.FUSED, team.FUSED, team.KEPT]
    assert np.array_equal(out.label[0, 1], tracks.label[0, 1])  # UAV 1 heard nobody


def test_the_assignment_pairs_as_many_tracks_as_the_gate_allows():
    # own tracks at 0 and 4, one sender's offers at 2 and -4.5 (d2 = dx^2 / 2, gated
    # below 5.15 m): the offer at 2 is nearest both, yet pairing it with the track at 4
    # leaves the offer at -4.5 to the track at 0: two pairs rather than one
    tracks = empty(1, 2, 3)
    for k, (x, label) in enumerate(((0.0, 10), (4.0, 20))):
        put(tracks, 0, 0, k, np.array([x, 0, 0, 0]), np.eye(4), label)
    for k, (x, label) in enumerate(((2.0, 7), (-4.5, 8))):
        put(tracks, 0, 1, k, np.array([x, 0, 0, 0]), np.eye(4), label)
    links = dense([[[True, True], [False, True]]])
    out, changed = team.team_round(tracks, tracks, links, GATE)
    assert out.label[0, 0].tolist() == [8, 7, -1]
    assert changed[0, 0].tolist() == [team.FUSED, team.FUSED, team.KEPT]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rule=st.sampled_from(team.RULES))
def test_foregone_components_resolve_as_the_assignments_do(seed, rule):
    # crowded targets, shared and private labels, tentative tracks, random links: the
    # components resolved without assignments give what the assignments give
    rng = np.random.default_rng(seed)
    B, n, K, m = 6, 6, 8, 4
    truth = np.zeros((B, m, 4))  # crowded to spread out: 4, 12 or 30 m
    truth[..., :2] = rng.uniform(0, 1, size=(B, m, 2)) * np.array([4, 12, 30] * 2)[:, None, None]
    tracks = empty(B, n, K)
    for b in range(B):
        for i in range(n):
            for k in range(K):
                if rng.random() < 0.4:
                    j = rng.integers(m)
                    label = j if rng.random() < 0.4 else 100 * (i + 1) + k  # shared or own
                    status = team.CONFIRMED if rng.random() < 0.8 else team.TENTATIVE
                    P = spd(rng, rng.uniform(0.5, 1.5))
                    error = rng.normal(size=4) * rng.uniform(0.5, 4)
                    put(tracks, b, i, k, truth[b, j] + error, P, label, status)
        for i in range(n):  # a UAV's labels are unique
            seen = set()
            for k in range(K):
                if tracks.label[b, i, k] in seen:
                    tracks.label[b, i, k], tracks.status[b, i, k] = -1, team.EMPTY
                seen.add(int(tracks.label[b, i, k]))
    links = dense(rng.random((B, n, n)) < 0.6)
    out, changed = team.team_round(tracks, tracks, links, GATE, rule)
    original = team._easy

    def nothing_foregone(*args):
        one, lone = original(*args)
        return np.zeros_like(one), np.zeros_like(lone)

    team._easy = nothing_foregone
    try:
        ref, ref_changed = team.team_round(tracks, tracks, links, GATE, rule)
    finally:
        team._easy = original
    assert np.array_equal(out.label, ref.label) and np.array_equal(out.status, ref.status)
    assert np.array_equal(changed, ref_changed)
    assert np.allclose(out.mean, ref.mean, rtol=1e-9, atol=1e-9)
    assert np.allclose(out.cov, ref.cov, rtol=1e-9, atol=1e-9)
    for b in range(B):
        for i in range(n):
            present = out.label[b, i][out.status[b, i] > 0]
            assert np.unique(present).size == present.size  # labels stay unique


def test_one_target_offered_under_several_labels_becomes_one_track():
    # UAVs 1 and 2 hold one target under labels 7 and 4; UAV 0, their neighbour,
    # first without it, then holding it under label 9
    for holds in (False, True):
        tracks = empty(1, 3, 2)
        x = np.array([50.0, 20, 1, 1])
        put(tracks, 0, 1, 0, x + 0.1, np.eye(4), 7)
        put(tracks, 0, 2, 1, x - 0.1, np.eye(4) * 2, 4)
        if holds:
            put(tracks, 0, 0, 1, x, np.eye(4) * 3, 9)
        out, changed = team.team_round(tracks, tracks, dense(np.ones((1, 3, 3))), GATE)
        present = out.status[0, 0] > 0
        assert out.label[0, 0][present].tolist() == [4]
        k = int(np.flatnonzero(present)[0])
        assert np.allclose(out.mean[0, 0, k], x + 0.1)  # UAV 1's, the most confident
        assert changed[0, 0, k] == (team.FUSED if holds else team.ADOPTED)


def test_two_tracks_of_one_sender_are_two_targets():
    # UAV 1 holds two close targets (labels 7, 8), both within UAV 0's gate around its
    # track of the first (label 10): the first joins UAV 0's track, the second is new
    tracks = empty(1, 2, 3)
    put(tracks, 0, 0, 0, np.zeros(4), np.eye(4), 10)
    put(tracks, 0, 1, 0, np.array([0.3, 0, 0, 0]), np.eye(4), 7)
    put(tracks, 0, 1, 1, np.array([2.0, 0, 0, 0]), np.eye(4), 8)
    links = dense([[[True, True], [False, True]]])
    out, changed = team.team_round(tracks, tracks, links, GATE)
    assert out.label[0, 0].tolist() == [7, 8, -1]
    assert changed[0, 0].tolist() == [team.FUSED, team.ADOPTED, team.KEPT]
    assert np.allclose(out.mean[0, 0, 1], [2.0, 0, 0, 0])

    # UAV 1 holds UAV 0's label 10 and, close by, label 6: a second target, not a
    # smaller label for the first
    tracks.label[0, 1, :2] = [10, 6]
    out, changed = team.team_round(tracks, tracks, links, GATE)
    assert out.label[0, 0].tolist() == [10, 6, -1]
    assert changed[0, 0].tolist() == [team.KEPT, team.ADOPTED, team.KEPT]


# ------------------------------------------------------------------ capacity


def test_a_full_uav_drops_an_offer_or_replaces_a_weaker_tentative_track():
    far = np.array([0.0, 1000, 0, 0])

    def case(second_status, second_cov):
        tracks = empty(1, 2, 2)
        put(tracks, 0, 0, 0, np.zeros(4), np.eye(4), 1)
        put(tracks, 0, 0, 1, -far, second_cov, 2, second_status)
        put(tracks, 0, 1, 0, far, np.eye(4) * 2, 3)  # the offer, confidence 1/8
        put(tracks, 0, 1, 1, 2 * far, np.eye(4) * 0.1, 4, team.TENTATIVE)  # never offered
        links = dense([[[True, True], [False, True]]])
        return team.team_round(tracks, tracks, links, GATE)

    out, changed = case(team.CONFIRMED, np.eye(4) * 10)  # full of confirmed tracks
    assert out.label[0, 0].tolist() == [1, 2] and (changed == team.KEPT).all()
    out, changed = case(team.TENTATIVE, np.eye(4) * 10)  # a weaker tentative track
    assert out.label[0, 0].tolist() == [1, 3]
    assert out.status[0, 0].tolist() == [team.CONFIRMED, team.CONFIRMED]
    assert np.allclose(out.mean[0, 0, 1], far)
    assert changed[0, 0].tolist() == [team.KEPT, team.ADOPTED]
    out, changed = case(team.TENTATIVE, np.eye(4) * 0.5)  # a stronger tentative track
    assert out.label[0, 0].tolist() == [1, 2] and (changed == team.KEPT).all()

    # two tentative tracks weaker than the offer: the least confident gives way
    tracks = empty(1, 2, 2)
    put(tracks, 0, 0, 0, np.zeros(4), np.eye(4) * 4, 1, team.TENTATIVE)
    put(tracks, 0, 0, 1, -far, np.eye(4) * 10, 2, team.TENTATIVE)
    put(tracks, 0, 1, 0, far, np.eye(4) * 2, 3)
    out, changed = team.team_round(tracks, tracks, dense([[[True, True], [False, True]]]), GATE)
    assert out.label[0, 0].tolist() == [1, 3]
    assert changed[0, 0].tolist() == [team.KEPT, team.ADOPTED]


# ------------------------------------------------------------------ the radio


@pytest.mark.parametrize("form", ["dense", "edges"])
def test_messages_count_as_the_consensus_counts_them(form):
    rng = np.random.default_rng(11)
    B, n, m = 3, 6, 2
    adj = np.stack([connected_graph(rng, n, 2) for _ in range(B)])
    tracks = empty(B, n, m)
    for b in range(B):
        for i in range(n):
            put(tracks, b, i, 0, rng.normal(size=4), spd(rng), 10 * i + b)
    rounds = rng.integers(0, 4, size=(B, n))
    radio, _ = lossy(adj, 0.3, form)
    agreed = team.agree(radio, tracks, rounds, GATE)
    sent, delivered = agreed.sent, agreed.delivered
    gamma = confidence(tracks.cov)
    radio, _ = lossy(adj, 0.3, form)
    oracle = fusion.consensus(
        radio, fusion.Estimates(gamma=gamma, source=fusion.identity(gamma.shape)), rounds
    )
    assert np.array_equal(sent, oracle.sent) and np.array_equal(delivered, oracle.delivered)
    assert (delivered < sent).any()


@pytest.mark.parametrize("form", ["dense", "edges"])
def test_a_receiver_uses_only_the_offers_delivered(form):
    B, n = 4, 5
    adj = network.complete(n, (B,))
    tracks = empty(B, n, n)
    for b in range(B):
        for i in range(n):  # UAV i holds target i, far from the others, label 10 i + 1
            put(tracks, b, i, 0, np.array([1000.0 * i, 0, 0, 0]), np.eye(4), 10 * i + 1)
    radio, realisation = lossy(adj, 0.5, form)
    agreed = team.agree(radio, tracks, np.ones((B, n), dtype=int), GATE)
    out, changed = agreed.tracks, agreed.changed
    t, i, q = np.nonzero(adj)
    lost = realisation.lost(0, "consensus", 1, t, q, i)
    assert lost.any() and (~lost).any()
    for b in range(B):
        for r in range(n):
            heard = q[(t == b) & (i == r) & ~lost]
            expected = sorted([10 * r + 1] + [10 * s + 1 for s in heard])
            assert sorted(out.label[b, r][out.status[b, r] > 0].tolist()) == expected
            assert (changed[b, r] == team.ADOPTED).sum() == heard.size


def test_bad_arguments_are_named():
    tracks = empty(1, 2, 2)
    links = dense(np.ones((1, 2, 2)))
    with pytest.raises(ValueError, match="fusion rule"):
        team.team_round(tracks, tracks, links, GATE, "average")
    with pytest.raises(ValueError, match="gate"):
        team.team_round(tracks, tracks, links, -1.0)
    with pytest.raises(ValueError, match="track cov"):
        TrackSet(
            mean=tracks.mean, cov=tracks.cov[..., :2], label=tracks.label, status=tracks.status
        )


@pytest.mark.parametrize("form", ["dense", "edges"])
def test_with_every_message_lost_every_uav_keeps_its_tracks(form):
    B, n = 2, 3
    tracks = empty(B, n, 2)
    for i in range(n):
        put(tracks, 0, i, 1, np.array([100.0 * i, 0, 0, 0]), np.eye(4), i + 1)
    radio, _ = lossy(network.complete(n, (B,)), 1.0, form)
    agreed = team.agree(radio, tracks, np.full((B, n), 2), GATE)
    out, changed, sent, delivered = agreed.tracks, agreed.changed, agreed.sent, agreed.delivered
    assert np.array_equal(out.label, tracks.label) and (changed == team.KEPT).all()
    assert sent.tolist() == [2 * n * (n - 1)] * B and delivered.tolist() == [0] * B


# ------------------------------------------------------------------ deletions that travel


def with_life(tracks, stamp, tombs):
    return TrackSet(
        mean=tracks.mean,
        cov=tracks.cov,
        label=tracks.label,
        status=tracks.status,
        stamp=np.asarray(stamp, dtype=np.int64),
        tombs=np.asarray(tombs, dtype=np.int64),
    )


def test_a_tombstone_empties_older_tracks_of_its_label_only():
    tracks = empty(1, 1, 3)
    for k, label in enumerate((7, 7, 8)):
        put(tracks, 0, 0, k, np.zeros(4), np.eye(4), label)
    tracks = TrackSet(
        mean=tracks.mean, cov=tracks.cov, label=np.array([[[7, 9, 8]]]), status=tracks.status
    )
    tombs = np.array([[[[7, 10], [9, 10], [-1, -1]]]])
    buried = team.bury(with_life(tracks, [[[5, 10, 3]]], tombs), tombs)
    # label 7 measured at 5 < 10: gone; label 9 measured at 10, after the deletion: kept
    assert buried.status[0, 0].tolist() == [0, 2, 2]
    assert buried.label[0, 0].tolist() == [-1, 9, 8]


def test_tombstones_keep_the_latest_step_of_each_label_and_the_latest_labels():
    tombs = np.full((1, 1, 3, 2), -1, dtype=np.int64)
    tombs = team.entomb(tombs, np.array([[[4, -1, 5]]]), 10)
    tombs = team.entomb(tombs, np.array([[[4, 6, -1]]]), 12)
    got = {tuple(t) for t in tombs[0, 0]}
    assert got == {(4, 12), (6, 12), (5, 10)}
    tombs = team.entomb(tombs, np.array([[[9, -1, -1]]]), 13)  # full: the oldest goes
    assert {tuple(t) for t in tombs[0, 0]} == {(4, 12), (6, 12), (9, 13)}


def test_a_deletion_travels_through_the_team_and_is_not_undone_by_its_copies():
    """On a path 0 - 1 - 2, UAV 0 deleted label 7 at step 10 where it looked; UAVs 1 and
    2 hold copies measured at step 5: after the rounds nobody holds it, and everyone
    knows the tombstone. A copy measured after the deletion (step 12) stands."""
    adjacency = np.array([[[0, 1, 0], [1, 0, 1], [0, 1, 0]]], dtype=bool)
    for stamp_2, kept in ((5, False), (12, True)):
        tracks = empty(1, 3, 2)
        put(tracks, 0, 1, 0, np.zeros(4), np.eye(4), 7)
        put(tracks, 0, 2, 0, np.zeros(4), np.eye(4), 7)
        tombs = np.full((1, 3, 2, 2), -1, dtype=np.int64)
        tombs[0, 0, 0] = (7, 10)
        start = with_life(tracks, [[[0, 0], [5, 0], [stamp_2, 0]]], tombs)
        agreed = team.agree(fusion.perfect_radio(adjacency), start, np.full((1, 3), 2), GATE)
        out, changed = agreed.tracks, agreed.changed
        assert out.tombs is not None and (out.tombs[0, :, :, 0] == 7).any(axis=1).all()
        holds = (out.label[0] == 7) & (out.status[0] == team.CONFIRMED)
        if kept:  # the fresher copy spreads back, and the tombstone stays below it
            assert holds.all(axis=None) or holds[2].any()
            assert (out.stamp[0][holds] == 12).all()
        else:
            assert not holds.any()
            assert changed[0, 1, 0] == team.EMPTIED and changed[0, 2, 0] == team.EMPTIED
