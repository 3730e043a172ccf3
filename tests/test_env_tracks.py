"""The multi-agent environment on tracks of unknown association (gnn, jpda): what a UAV
observes are its confirmed tracks, the state the team's labels, the trial `simulate`'s."""

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

import uavtrack
from uavtrack.testing import assert_same_trace

pytest.importorskip("pettingzoo")
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test  # noqa: E402
from pettingzoo.test.state_test import state_test  # noqa: E402

import uavtrack.env as uavenv  # noqa: E402
from uavtrack.env import parallel_env, vector_env  # noqa: E402
from uavtrack.env.spaces import TARGET, TARGET_STATE, UAV_STATE  # noqa: E402

JPDA = {
    "tracker": {"association": "jpda"},
    "sensor": {"detection_probability": 0.9, "clutter_rate": 2},
}
GNN = {"tracker": {"association": "gnn"}, "sensor": {"clutter_rate": 1}}
BIRTHS = {**JPDA, "target": {"stay": 8, "away": 5}, "planner": {"existence": True}}
RHO = 425 * math.tan(math.radians(5))  # the observation radius of the paper's scenario
GATE = chi2.ppf(0.99, 2)  # tracker.gate_probability's default


def fly(env, seed, until=None):
    """Fly the method's actions from reset(seed) to the end (or `until` steps); yields
    (observations, infos) of every cycle before its step."""
    observations, infos = env.reset(seed=seed)
    k = 0
    while env.agents and (until is None or k < until):
        yield observations, infos
        observations, _, _, _, infos = env.step({a: infos[a]["paper_action"] for a in env.agents})
        k += 1


def own_gate(pending):
    """(Nu, K) of trial 0: a measurement of the UAV's own scan lies in the 99 % gate of a
    confirmed track's fused estimate, each pair computed apart with numpy's inverse."""
    t, scan = pending.tracks, pending.scan
    Nu, K = t.book.label.shape[1:]
    out = np.zeros((Nu, K), dtype=bool)
    for i in range(Nu):
        for j in range(K):
            if not (t.book.status[0, i, j] == 2 and pending.alive[0, i]):
                continue
            for z, R, ok in zip(scan.z[0, i], scan.R[0, i], scan.valid[0, i], strict=True):
                nu = z - t.mean[0, i, j, :2]
                S = t.cov[0, i, j, :2, :2] + R
                out[i, j] |= bool(ok) and nu @ np.linalg.inv(S) @ nu <= GATE
    return out


# ---------------------------------------------------------------- the same trial


@pytest.mark.parametrize(
    "method,settings",
    [("distributed", JPDA), ("centralized", GNN), ("greedy", JPDA), ("distributed", BIRTHS)],
    ids=["distributed-jpda", "centralized-gnn", "greedy-jpda", "distributed-births"],
)
def test_paper_actions_through_the_env_are_simulate_with_tracks(method, settings):
    env = parallel_env(method_for_others=method, steps=30, **settings)
    for _ in fly(env, seed=4):
        pass
    ours = env.result()
    scenario = uavtrack.Scenario(steps=30).with_overrides(
        {f"{part}.{k}": v for part, values in settings.items() for k, v in values.items()}
    )
    reference = uavtrack.simulate(scenario, method, seed=4)
    assert_same_trace(ours.trace, reference.trace)
    for name in ("observation_rate", "gospa", "messages"):
        assert getattr(ours, name) == pytest.approx(getattr(reference, name), rel=1e-12)


def test_team_reward_stays_on_the_truth_with_tracks():
    env = parallel_env(steps=30, **JPDA)
    observations, infos = env.reset(seed=2)
    total = 0.0
    while env.agents:
        observations, rewards, *_, infos = env.step({})
        total += rewards["uav_0"]
    seen = env.result().trace.observed.any(axis=1).mean(axis=1)  # the truth in some disk
    assert math.isclose(total, seen[1:].sum(), rel_tol=1e-12)
    assert math.isclose((total + seen[0]) / 30, env.result().observation_rate, rel_tol=1e-12)


def test_the_information_reward_is_refused_with_tracks_in_one_line():
    for make in (lambda: parallel_env(reward="information", **GNN),
                 lambda: vector_env(2, reward="information", **JPDA)):  # fmt: skip
        with pytest.raises(uavtrack.ScenarioError, match="reward 'information'") as caught:
            make()
        assert "\n" not in str(caught.value)


# ---------------------------------------------------------------- observations


def test_box_rows_are_the_confirmed_tracks_nearest_first():
    env = parallel_env(steps=25, **JPDA)
    lay = env.spaces.layout()
    assert env.spaces.max_targets == 4  # the briefed targets' count by default
    met_any = unmet_any = born = False
    for observations, infos in fly(env, seed=3):
        pending = env._run.pending
        t = pending.tracks
        gated = own_gate(pending)
        for i in range(5):
            x, y, _, _, psi = pending.believed[0, i]
            confirmed = np.flatnonzero(t.book.status[0, i] == 2)
            means = t.mean[0, i, confirmed, :2]
            order = np.argsort(np.hypot(*(means - [x, y]).T), kind="stable")[:4]
            rows = observations[f"uav_{i}"][lay["targets"]].reshape(4, len(TARGET))
            n = len(order)
            assert rows[:, 0].tolist() == [1.0] * n + [0.0] * (4 - n)
            assert not rows[n:].any()
            got = []
            for row in rows[:n]:
                r = dict(zip(TARGET, row, strict=True))
                d = RHO * math.expm1(r["distance"])
                b = math.atan2(r["sin_bearing"], r["cos_bearing"])
                got.append((x + d * math.cos(psi + b), y + d * math.sin(psi + b)))
            assert np.allclose(got, means[order].reshape(-1, 2), atol=1e-2)
            in_view = rows[:n, TARGET.index("in_view")]
            assert in_view.tolist() == gated[i, confirmed[order]].astype(float).tolist()
            met_any |= bool(in_view.any())
            unmet_any |= bool((in_view == 0).any())
            # the target followed: a label the UAV holds confirmed, or none
            label = infos[f"uav_{i}"]["target"]
            assert label == -1 or label in t.book.label[0, i, confirmed]
            born |= label >= 4
            assert infos[f"uav_{i}"]["in_view"] == int(gated[i].sum())
    assert met_any and unmet_any and born  # every case above was met on the way


def test_the_observation_reads_no_truth():
    env = parallel_env(steps=10, **JPDA)
    env.reset(seed=1)
    env.step({})
    view = env._run.view()
    flipped = replace(view, observed=~view.observed, uavs=view.uavs + 50.0)
    assert np.array_equal(env.spaces.observe(view), env.spaces.observe(flipped))
    known = parallel_env(steps=10)
    known.reset(seed=1)
    known.step({})
    view = known._run.view()  # the paper's "in view": the targets the UAV measured
    assert view.detected is not None
    flipped = replace(view, observed=~view.observed)  # the truth's disks: not read
    assert np.array_equal(known.spaces.observe(view), known.spaces.observe(flipped))
    flipped = replace(view, detected=~view.detected)
    assert not np.array_equal(known.spaces.observe(view), known.spaces.observe(flipped))


def test_max_targets_ranges_over_the_track_slots():
    env = parallel_env(steps=5, max_targets=12, **JPDA)  # K = 2 x 4 + 4
    observations, _ = env.reset(seed=0)
    assert observations["uav_0"].shape == (8 + 12 * len(TARGET) + 4 * 6,)
    assert env.state().shape == (1 + 5 * len(UAV_STATE) + 12 * len(TARGET_STATE),)
    with pytest.raises(ValueError, match=r"max_targets must be in \[1, 12\]"):
        parallel_env(max_targets=13, **JPDA)


def test_dict_observations_hold_the_confirmed_tracks_and_their_labels():
    env = parallel_env(steps=15, observation="dict", **JPDA)
    seen_tentative = False
    for observations, _ in fly(env, seed=3):
        t = env._run.pending.tracks
        for i in range(5):
            o = observations[f"uav_{i}"]
            assert env.observation_space(f"uav_{i}").contains(o)
            confirmed = t.book.status[0, i] == 2
            assert np.array_equal(o["labels"], np.where(confirmed, t.book.label[0, i], -1))
            assert np.array_equal(o["estimates"][confirmed], t.mean[0, i, confirmed])
            assert o["covariance"][confirmed, 2] == pytest.approx(
                t.cov[0, i, confirmed, 0, 1], rel=1e-12
            )
            assert not o["estimates"][~confirmed].any()
            seen_tentative |= bool((t.book.status[0, i] == 1).any())
    assert seen_tentative  # some slot held a track not confirmed, and it was left out


# ---------------------------------------------------------------- state


def test_state_rows_are_the_teams_labels_most_confident_first():
    env = parallel_env(steps=20, **JPDA)
    checked_seen = False
    for _ in fly(env, seed=5):
        pending = env._run.pending
        t = pending.tracks
        gated = own_gate(pending)
        best = {}  # label -> (confidence, mean, cov, any UAV's own scan met it)
        for i in np.flatnonzero(pending.alive[0]):
            for j in np.flatnonzero(t.book.status[0, i] == 2):
                label = int(t.book.label[0, i, j])
                gamma = 1 / np.trace(t.cov[0, i, j])
                hit = bool(gated[i, j]) or best.get(label, (0, 0, 0, False))[3]
                if label not in best or gamma > best[label][0]:
                    best[label] = (gamma, t.mean[0, i, j], t.cov[0, i, j], hit)
                else:
                    best[label] = best[label][:3] + (hit,)
        state = env.state()
        assert env.state_space.contains(state)
        rows = state[1 + 5 * len(UAV_STATE) :].reshape(4, len(TARGET_STATE))
        labels = sorted(best)[:4]
        assert rows[:, 0].tolist() == [1.0] * len(labels) + [0.0] * (4 - len(labels))
        for row, label in zip(rows, labels, strict=False):
            _, m, P, hit = best[label]
            assert row[1:5] == pytest.approx(
                [(m[0] - 100) / 100, (m[1] - 100) / 100, m[2] / 15, m[3] / 15], abs=1e-5
            )
            sigma = math.sqrt((P[0, 0] + P[1, 1]) / 2)
            assert row[5] == pytest.approx(math.log(sigma / RHO), abs=1e-5)
            assert row[6] == float(hit)
            checked_seen |= hit
    assert checked_seen


# ---------------------------------------------------------------- PettingZoo's tests


def test_pettingzoo_parallel_aec_and_state_api_with_tracks():
    parallel_api_test(parallel_env(steps=15, **JPDA), num_cycles=20)
    api_test(uavenv.env(steps=15, **GNN), num_cycles=20)
    api_test(uavenv.env(steps=15, observation="dict", **JPDA), num_cycles=20)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NaN, no infinity, the right shapes
        state_test(uavenv.env(steps=15, **JPDA), parallel_env(steps=15, **JPDA), num_cycles=20)
    parallel_seed_test(lambda: parallel_env(steps=15, **JPDA), num_cycles=20)


def test_a_failed_uav_leaves_with_its_tracks():
    env = parallel_env(steps=20, faults={"failures": [[1, 6]]}, **JPDA)
    for k, (observations, _) in enumerate(fly(env, seed=0, until=10)):
        assert ("uav_1" in observations) == (k <= 6)  # its last, terminated
    view = env._run.view()
    assert not view.alive[0, 1] and (view.label[0, 1] == -1).all()  # holds no track now
    assert (view.label[0, 0] >= 0).any()
    rows = env.state()[1:].reshape(-1)[: 5 * len(UAV_STATE)].reshape(5, len(UAV_STATE))
    assert rows[1].tolist() == [0.0] * len(UAV_STATE) and rows[0, 0] == 1.0
