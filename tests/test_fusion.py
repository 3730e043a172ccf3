from dataclasses import replace

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import uavtrack
from uavtrack import fusion, network


def graph(n, edges):
    adj = np.zeros((n, n), dtype=bool)
    for a, b in edges:
        adj[a, b] = adj[b, a] = True
    return adj


def component_max_index(confidence, adj):
    """Oracle: for each (i, j), the UAV of i's component with the highest confidence."""
    g = nx.from_numpy_array(adj.astype(int))
    out = np.empty(confidence.shape, dtype=int)
    for comp in nx.connected_components(g):
        comp = sorted(comp)
        best = np.array(comp)[np.argmax(confidence[comp], axis=0)]
        out[comp] = best
    return out


def eccentricities(adj):
    g = nx.from_numpy_array(adj.astype(int))
    ecc = np.zeros(len(adj), dtype=int)
    for comp in nx.connected_components(g):
        sub = g.subgraph(comp)
        for node, e in nx.eccentricity(sub).items():
            ecc[node] = e
    return ecc


def test_relay_on_path_m_j_i():
    # m = 0, j = 1, i = 2; j's eccentricity is 1 but i needs 2 rounds and gets m's value via j
    adj = graph(3, [(0, 1), (1, 2)])
    confidence = np.array([[9.0], [1.0], [2.0]])
    source, rounds = fusion.max_consensus(confidence, adj)
    assert rounds.tolist() == [2, 1, 2]
    assert source[:, 0].tolist() == [0, 0, 0]
    # one round less and i cannot have it: D_i is needed
    short = fusion.consensus_rounds(confidence, adj, np.array([2, 1, 1]))
    assert short[2, 0] != 0


def test_star_center_one_round_leaves_two():
    adj = graph(6, [(0, k) for k in range(1, 6)])
    confidence = np.arange(6.0)[:, None] * np.array([1.0, -1.0])  # leaf 5 max, then centre max
    source, rounds = fusion.max_consensus(confidence, adj)
    assert rounds.tolist() == [1, 2, 2, 2, 2, 2]
    assert (source[:, 0] == 5).all() and (source[:, 1] == 0).all()


def test_long_path_needs_eccentricity_rounds():
    n = 7
    adj = graph(n, [(k, k + 1) for k in range(n - 1)])
    confidence = np.zeros((n, 1))
    confidence[0] = 1.0
    source, rounds = fusion.max_consensus(confidence, adj)
    assert rounds.tolist() == [max(k, n - 1 - k) for k in range(n)]
    assert (source == 0).all()


def test_isolated_uavs_keep_their_own():
    adj = np.zeros((4, 4), dtype=bool)
    confidence = np.random.default_rng(0).random((4, 3))
    source, rounds = fusion.max_consensus(confidence, adj)
    assert (rounds == 0).all()
    assert (source == np.arange(4)[:, None]).all()


@st.composite
def geometric_graphs(draw):
    n = draw(st.integers(1, 14))
    pts = np.array(
        draw(st.lists(st.tuples(st.floats(0, 100), st.floats(0, 100)), min_size=n, max_size=n))
    )
    radius = draw(st.floats(0, 60))
    uavs = np.zeros((n, 5))
    uavs[:, :2] = pts
    adj = network.adjacency(uavs, radius)
    m = draw(st.integers(1, 4))
    seed = draw(st.integers(0, 2**32 - 1))
    confidence = np.random.default_rng(seed).random((n, m))
    return adj, confidence


@pytest.mark.parametrize("form", ["dense", "edges"])
@settings(max_examples=150, deadline=None)
@given(case=geometric_graphs())
def test_max_consensus_on_random_geometric_graphs(form, case):
    check_max_consensus(*case, form)


def check_max_consensus(adj, confidence, form):
    source, rounds = fusion.max_consensus(confidence, adj, form)
    ecc = eccentricities(adj)
    # D_i, learned by the flooding protocol, is i's eccentricity in its component
    assert np.array_equal(rounds, ecc)
    # every UAV ends with its component's maximum, never a value from elsewhere
    assert np.array_equal(source, component_max_index(confidence, adj))
    # and D_i rounds are needed: with the maximum at i's farthest UAV, D_i - 1 do not suffice
    dist = dict(nx.all_pairs_shortest_path_length(nx.from_numpy_array(adj.astype(int))))
    for i in np.flatnonzero(ecc > 0):
        far = max(dist[i], key=dist[i].get)
        probe = np.zeros((len(adj), 1))
        probe[far] = 1.0
        fewer = rounds.copy()
        fewer[i] -= 1
        assert fusion.consensus_rounds(probe, adj, fewer, form)[i, 0] != far
        assert fusion.consensus_rounds(probe, adj, rounds, form)[i, 0] == far


@pytest.mark.parametrize("form", ["dense", "edges"])
@settings(max_examples=30, deadline=None)
@given(cases=st.lists(geometric_graphs(), min_size=2, max_size=4))
def test_batched_consensus_equals_one_graph_at_a_time(form, cases):
    check_batched(cases, form)


def check_batched(cases, form):
    n = min(a.shape[0] for a, _ in cases)
    m = min(c.shape[1] for _, c in cases)
    adj = np.stack([a[:n, :n] for a, _ in cases])
    conf = np.stack([c[:n, :m] for _, c in cases])
    batched = fusion.fuse(conf, adj, form)
    for b in range(len(cases)):
        alone = fusion.fuse(conf[b], adj[b], form)
        assert np.array_equal(batched.source[b], alone.source)
        assert np.array_equal(batched.rounds[b], alone.rounds)
        assert batched.messages[b] == alone.messages


def test_messages_count_edges_times_rounds():
    adj = graph(3, [(0, 1), (1, 2)])
    result = fusion.fuse(np.ones((3, 2)), adj)
    # degrees (1, 2, 1) times rounds (2, 1, 2)
    assert result.messages == 1 * 2 + 2 * 1 + 1 * 2


def test_gather_picks_source_rows(rng):
    values = rng.normal(size=(2, 3, 4, 4, 4))
    source = rng.integers(0, 3, (2, 3, 4))
    out = fusion.gather(source, values)
    for b in range(2):
        for i in range(3):
            for j in range(4):
                assert np.array_equal(out[b, i, j], values[b, source[b, i, j], j])


def test_adjacency_uses_3d_distance():
    uavs = np.zeros((3, 5))
    uavs[:, 2] = [500.0, 540.0, 500.0]
    uavs[2, 0] = 45.0
    adj = network.adjacency(uavs, 50.0)
    assert adj[0, 1] and adj[0, 2] and not adj[1, 2]  # sqrt(45^2 + 40^2) > 50
    assert not adj.diagonal().any() and np.array_equal(adj, adj.T)
    assert not network.adjacency(uavs, 0.0).any()


@pytest.mark.parametrize("n", [1, 2, 5])
def test_complete_graph_one_round(n):
    source, rounds = fusion.max_consensus(np.arange(float(n))[:, None], network.complete(n))
    assert (rounds == (1 if n > 1 else 0)).all() and (source == n - 1).all()


def test_large_team_uses_edge_lists_and_agrees_with_dense(rng):
    uavs = np.zeros((2, 60, 5))
    uavs[..., :2] = rng.uniform(0, 300, (2, 60, 2))
    adj = network.adjacency(uavs, 50.0)
    confidence = rng.random((2, 60, 7))
    rounds, _ = fusion.eccentricity(adj)
    assert network.SPARSE_FROM <= 60 and network.links(adj).edges
    sparse = fusion.consensus_rounds(confidence, adj, rounds)
    dense = fusion.consensus_rounds(confidence, adj, rounds, "dense")
    assert np.array_equal(fusion.eccentricity(adj, "dense")[0], rounds)
    assert np.array_equal(sparse, dense)
    for b in range(2):
        assert np.array_equal(sparse[b], component_max_index(confidence[b], adj[b]))


def test_self_loops_in_a_given_adjacency_are_ignored():
    # UAV 2 is isolated; a diagonal marked True must not make it its own neighbour
    adj = graph(3, [(0, 1)]) | np.eye(3, dtype=bool)
    confidence = np.array([[1.0], [5.0], [9.0]])
    source, rounds = fusion.max_consensus(confidence, adj)
    assert rounds.tolist() == [1, 1, 0]
    assert source[:, 0].tolist() == [1, 1, 2]
    assert fusion.fuse(confidence, adj).messages == 2


@st.composite
def teams(draw):
    """B trials of n UAVs at random 3-D positions, some failed, and a radio range."""
    b, n = draw(st.integers(1, 3)), draw(st.integers(1, 70))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    uavs = np.zeros((b, n, 5))
    side = draw(st.floats(10, 600))
    uavs[..., :2] = rng.uniform(0, side, (b, n, 2))
    uavs[..., 2] = 400 + rng.uniform(0, draw(st.floats(0, 60)), (b, n))
    alive = rng.random((b, n)) > draw(st.floats(0, 0.5))
    return uavs, alive, draw(st.floats(0, 120))


@settings(max_examples=80, deadline=None)
@given(case=teams())
def test_radio_links_from_the_grid_equal_the_dense_relation(case):
    uavs, alive, radius = case
    dense = network.adjacency(uavs, radius) & alive[:, :, None] & alive[:, None, :]
    for form in ("dense", "edges"):
        links = network.radio_links(uavs, alive, radius, form)
        assert links.edges == (form == "edges")
        assert np.array_equal(links.adjacency(), dense)
    edges = network.radio_links(uavs, alive, radius, "edges")
    # sorted by (trial, receiver, sender), every node's self-link present
    key = (edges.trial * uavs.shape[1] + edges.receiver) * uavs.shape[1] + edges.sender
    assert (np.diff(key) > 0).all() and edges.own.sum() == alive.size


@pytest.mark.parametrize("spacing", [1.0, 0.5, 0.7071067811865476])
def test_grid_pairs_keep_pairs_exactly_at_range_on_cell_borders(spacing):
    """Positions on a lattice whose points fall on the cells' borders, at negative
    coordinates too: every pair within range once, as the all-pairs check finds."""
    r = 100.0
    g = np.arange(-6, 7) * r * spacing
    pos = np.array([(x, y, 50.0) for x in g for y in g] + [(g[0], g[0], 50.0)] * 3)
    i, q = network.grid_pairs(pos, r)
    pairs = {tuple(sorted(p)) for p in zip(i.tolist(), q.tolist(), strict=True)}
    assert len(pairs) == i.size and (i != q).all()  # each unordered pair once
    found = {p for p in pairs if network.in_range(pos[p[0]] - pos[p[1]], r)}
    a, b = np.triu_indices(len(pos), 1)
    keep = network.in_range(pos[a] - pos[b], r)
    assert found == set(zip(a[keep].tolist(), b[keep].tolist(), strict=True))


@pytest.mark.parametrize("form", ["dense", "edges"])
@settings(max_examples=60, deadline=None)
@given(case=geometric_graphs())
def test_the_flooding_learns_the_largest_neighbourhood_of_each_uav(form, case):
    adj, _ = case
    n = len(adj)
    radio = fusion.perfect_radio(adj[None], form)
    depth = fusion.learn_depth(radio, np.ones((1, n), dtype=bool))
    closed = adj | np.eye(n, dtype=bool)
    size = closed.sum(axis=1)
    expected = [size[closed[i]].max() for i in range(n)]  # over i and its neighbours
    assert depth.largest[0].tolist() == expected


def test_rounds_run_only_on_the_receivers_still_running():
    # a path 0-1-2-3 and a pair 4-5: the pair stops after one round, the path runs three
    adj = graph(6, [(0, 1), (1, 2), (2, 3), (4, 5)])
    links = network.links(adj[None], "edges")
    running = np.array([[True, True, True, True, False, False]])
    into = links.into(running)
    assert set(into.receiver.tolist()) == {0, 1, 2, 3}
    heads = into.heads
    assert heads[1].tolist() == [0, 1, 2, 3] and into.ordinal[-1] == 3
    # a receiver with no links keeps its own tuple
    gamma = np.arange(6.0)[None, :, None]
    best = fusion.adopt(gamma, gamma, into)
    assert best[0, :, 0].tolist() == [1, 2, 3, 3, 4, 5]


# ------------------------------------------------------------------ with the measurement gate


def spd(rng, shape, scale=1.0):
    """Random symmetric positive definite 4 x 4 matrices of `shape`."""
    a = rng.normal(size=shape + (4, 4)) * scale
    return a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(4)


@pytest.mark.parametrize("seed", range(6))
def test_adopt_and_intersect_with_a_mask_agree_in_both_forms(seed):
    # the same admitted tuples in the dense and the edge layout give the same choice
    from uavtrack.robust import gate

    rng = np.random.default_rng(seed)
    B, n, m = 2, 6, 3
    adj = rng.random((B, n, n)) < 0.5
    adj = adj | np.swapaxes(adj, 1, 2)
    dense, edges = network.links(adj, "dense"), network.links(adj, "edges")
    cov = spd(rng, (B, n, m))
    tuples = fusion.Estimates(
        mean=rng.normal(size=(B, n, m, 4)) * 3,
        cov=cov,
        gamma=1.0 / np.trace(cov, axis1=-2, axis2=-1),
    )
    observed = rng.random((B, n, m)) < 0.6
    z = rng.normal(size=(B, n, m, 2)) * 3
    R = np.broadcast_to(np.eye(2), (B, n, m, 2, 2)).copy()
    measured = gate.Measured(observed, z, R, rng.random((B, n, m)) < 0.5)
    estimates = (tuples.mean, tuples.cov)
    masks = [gate.admitted(links, estimates, estimates, measured, 2.0) for links in (dense, edges)]
    t, i, q = edges.pairs()
    assert np.array_equal(masks[0][t, i, q], masks[1])
    assert not masks[0].all() and masks[0].any()  # the gate bites in both directions
    a = [
        fusion.adopt(tuples.gamma, tuples.gamma, lk, mk)
        for lk, mk in zip((dense, edges), masks, strict=True)
    ]
    assert np.array_equal(a[0], a[1])
    # what is chosen is admitted, or the receiver's own where nothing is
    b_, i_, j_ = np.indices(a[0].shape)
    chosen = masks[0][b_, i_, a[0], j_]
    assert (chosen | (a[0] == i_)).all()
    ci = [
        fusion.intersect_round(tuples, tuples, lk, mk)
        for lk, mk in zip((dense, edges), masks, strict=True)
    ]
    for name in ("mean", "cov"):
        assert np.allclose(getattr(ci[0], name), getattr(ci[1], name), rtol=1e-9, atol=1e-12)


def test_adopt_without_an_admitted_candidate_keeps_its_own():
    adj = graph(3, [(0, 1), (1, 2)])[None]
    gamma = np.array([[[5.0], [1.0], [9.0]]])
    for form in ("dense", "edges"):
        links = network.links(adj, form)
        t, i, q = links.pairs()
        shape = np.broadcast_shapes(t.shape, i.shape, q.shape) + (1,)
        nothing = np.zeros(shape, dtype=bool)
        assert fusion.adopt(gamma, gamma, links, nothing)[0, :, 0].tolist() == [0, 1, 2]
        everything = np.ones(shape, dtype=bool)
        assert fusion.adopt(gamma, gamma, links, everything)[0, :, 0].tolist() == [0, 2, 2]


def test_an_estimate_of_no_confidence_takes_no_part_in_intersection(rng):
    # -inf: no estimate (a member's estimate beyond the plausibility bounds); the others'
    # fusion is what it is without it
    adj = np.ones((1, 3, 3), dtype=bool)
    cov = spd(rng, (1, 3, 1))
    mean = rng.normal(size=(1, 3, 1, 4))
    gamma = 1.0 / np.trace(cov, axis1=-2, axis2=-1)
    tuples = fusion.Estimates(mean=mean, cov=cov, gamma=gamma)
    silenced = replace(tuples, gamma=np.where(np.arange(3)[None, :, None] == 2, -np.inf, gamma))
    links = network.links(adj, "dense")
    fused = fusion.intersect_round(tuples, silenced, links)
    pair = network.links(adj[:, :2, :2], "dense")
    two = tuples.map(lambda v: v[:, :2])
    expected = fusion.intersect_round(two, two, pair)
    assert np.allclose(fused.mean[:, :2], expected.mean, rtol=1e-12)
    assert np.allclose(fused.cov[:, :2], expected.cov, rtol=1e-12)


def test_consensus_tuples_are_a_record_whose_fields_travel_together():
    # two UAVs linked, one target: UAV 1's tuple is the more confident, and UAV 0 adopts
    # all of it (confidence, estimate, stamp), not the confidence alone
    own = fusion.Estimates(
        gamma=np.array([[[1.0], [3.0]]]),
        mean=np.array([[[[1.0, 2.0, 0.0, 0.0]], [[7.0, 8.0, 0.0, 0.0]]]]),
        stamp=np.array([[[4], [5]]]),
    )
    links = network.links(np.ones((1, 2, 2), dtype=bool), "dense")
    picked = fusion.pick(own, own, fusion.adopt(own.gamma, own.gamma, links))
    assert isinstance(picked, fusion.Estimates) and picked.cov is None
    assert picked.gamma[0, :, 0].tolist() == [3.0, 3.0]
    assert picked.mean[0, :, 0, :2].tolist() == [[7.0, 8.0], [7.0, 8.0]]
    assert picked.stamp[0, :, 0].tolist() == [5, 5]
    # a message's content in, the same content out: the tuple fields by name, in the
    # order of an agent's consensus message (`agents.messages.Spec`); other entries left
    from uavtrack.agents.messages import Spec

    scenario = uavtrack.Scenario(n_targets=1)
    names = list(Spec.of(scenario, False).contents("consensus"))
    content = {name: np.zeros(1, dtype=np.int64) for name in names}
    assert [name for name, _ in fusion.Estimates.of(content).items()] == names
    download = {name: np.zeros(1) for name in ("gamma", "mean", "cov", "stamp", "target")}
    assert [name for name, _ in fusion.Estimates.of(download).items()][-1] == "stamp"
