"""The multi-agent environment: the simulator's own cycle, the agents' actions, and
PettingZoo's own test utilities."""

import importlib
import math
import sys
import warnings

import numpy as np
import pytest

import uavtrack
from uavtrack.testing import assert_same_trace

pytest.importorskip("pettingzoo")
from pettingzoo.test import (  # noqa: E402
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
)
from pettingzoo.test.state_test import state_test  # noqa: E402

import uavtrack.env as uavenv  # noqa: E402
from uavtrack.env import parallel_env  # noqa: E402
from uavtrack.env.spaces import NEIGHBOUR, OWN, TARGET  # noqa: E402


def fly(env, policy, seed):
    observations, infos = env.reset(seed=seed)
    total = {a: 0.0 for a in env.possible_agents}
    while env.agents:
        actions = {a: policy(a, observations[a], infos[a]) for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        for a, r in rewards.items():
            total[a] += r
    return total


def paper(agent, observation, info):
    return info["paper_action"]


# ---------------------------------------------------------------- the same cycle


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_paper_actions_through_the_env_are_simulate(method):
    env = parallel_env(method_for_others=method, steps=50)
    fly(env, paper, seed=4)
    ours = env.result()
    reference = uavtrack.simulate(uavtrack.Scenario(steps=50), method, seed=4)
    assert_same_trace(ours.trace, reference.trace)
    for name in ("observation_rate", "rmse", "nees", "ospa_best", "messages"):
        assert getattr(ours, name) == getattr(reference, name)


@pytest.mark.parametrize(
    ("method", "radio"),
    [
        ("distributed", {"encoding": "compact", "bandwidth_bps": 2e5}),
        ("greedy", {"encoding": "compact"}),
        ("centralized", {"bandwidth_bps": 2e5}),
    ],
)
def test_a_radio_with_a_byte_budget_through_the_env_is_simulate(method, radio):
    fusion = {"trigger": 0.1} if method != "centralized" else {}
    env = parallel_env(method_for_others=method, steps=40, radio=radio, fusion=fusion)
    fly(env, paper, seed=4)
    ours = env.result()
    scenario = uavtrack.Scenario(steps=40, radio=radio, fusion=fusion)
    reference = uavtrack.simulate(scenario, method, seed=4)
    assert ours.trace is not None and reference.trace is not None
    assert_same_trace(ours.trace, reference.trace)  # the bytes among the counters
    assert ours.bytes == reference.bytes > 0


def test_agents_left_out_fly_the_method():
    env = parallel_env(steps=30)
    fly(env, paper, seed=1)
    full = env.result()
    env.reset(seed=1)
    while env.agents:
        env.step({})  # nobody acts: every UAV flies the paper's method
    assert_same_trace(env.result().trace, full.trace)


def test_other_actions_change_the_flight_not_the_stages():
    env = parallel_env(steps=25)
    fly(env, lambda a, o, info: 1, seed=0)  # everybody straight
    trace = env.result().trace
    assert np.all(trace.action == 0.0)
    headings = trace.uavs[..., 4]
    assert np.allclose(headings, headings[0])  # nobody turns
    assert trace.observed.shape == (25, 5, 4)


def test_changing_an_observation_changes_nothing_of_the_trial():
    def meddle(a, o, info):  # a common normalisation, in place on what the env handed out
        o[:] = 0.0
        return info["paper_action"]

    def meddle_dict(a, o, info):
        o["estimates"][:, :2] -= o["uav"][:2]
        o["uav"][:] = 0.0
        return info["paper_action"]

    reference = uavtrack.simulate(uavtrack.Scenario(steps=30), "distributed", seed=2)
    for observation, policy in (("box", meddle), ("dict", meddle_dict)):
        env = parallel_env(steps=30, observation=observation)
        fly(env, policy, seed=2)
        assert_same_trace(env.result().trace, reference.trace)


# ---------------------------------------------------------------- rewards


def test_team_reward_is_the_observation_rate_per_step():
    env = parallel_env(steps=40)
    total = fly(env, paper, seed=2)
    trace = env.result().trace
    seen = trace.observed.any(axis=1).mean(axis=1)  # share of targets in view, per step
    # every agent earns the team's share at the next cycle; the first cycle is no action's
    assert len(set(total.values())) == 1
    assert math.isclose(total["uav_0"], seen[1:].sum(), rel_tol=1e-12)
    assert math.isclose(
        (total["uav_0"] + seen[0]) / 40, env.result().observation_rate, rel_tol=1e-12
    )


def test_difference_reward_counts_what_only_this_uav_sees():
    env = parallel_env(steps=40, reward="difference", n_uavs=5, comm_range=200)
    total = fly(env, paper, seed=3)
    o = env.result().trace.observed[1:]  # (T-1, Nu, Nt)
    alone = (o & (o.sum(axis=1, keepdims=True) == 1)).sum(axis=(0, 2)) / 4
    assert [total[f"uav_{i}"] for i in range(5)] == pytest.approx(alone.tolist(), abs=1e-12)
    team = o.any(axis=1).sum() / 4
    assert sum(total.values()) <= team + 1e-12  # shared sightings earn nobody


def test_information_reward_is_the_gain_of_the_uavs_own_measurements():
    env = parallel_env(steps=30, reward="information")
    observations, infos = env.reset(seed=5)
    gains = []
    run = env._run
    while env.agents:
        actions = {a: infos[a]["paper_action"] for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        if run.pending is None:
            break
        prior = run.state.cov[0, ..., :2, :2]  # each UAV's belief before its measurement
        posterior = run.pending.belief[1][0, ..., :2, :2]
        seen = run.pending.observed[0]
        expected = 0.5 * np.log(np.linalg.det(prior) / np.linalg.det(posterior))
        expected = np.where(seen, expected, 0.0).sum(axis=1)
        got = np.array([rewards[f"uav_{i}"] for i in range(5)])
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-12)
        gains.append(got)
    gains = np.array(gains)
    assert (gains >= 0).all() and gains.sum() > 0  # a measurement never loses information


def test_the_papers_policy_earns_more_than_circling_and_random():
    rng = np.random.default_rng(0)
    policies = {
        "paper": paper,
        "circling": lambda a, o, info: 2,  # always bank +phi
        "random": lambda a, o, info: int(rng.integers(3)),
    }
    earned = {name: [] for name in policies}
    env = parallel_env(steps=120)
    for seed in (101, 102, 103):  # seeds no test of the env tunes on
        for name, policy in policies.items():
            earned[name].append(fly(env, policy, seed)["uav_0"])
    paper_mean = np.mean(earned["paper"])
    assert paper_mean > 1.5 * np.mean(earned["circling"])
    assert paper_mean > 1.5 * np.mean(earned["random"])


# ---------------------------------------------------------------- observations and state


def test_box_observations_are_egocentric_and_scaled():
    env = parallel_env(steps=10)
    observations, infos = env.reset(seed=7)
    env.step({a: infos[a]["paper_action"] for a in env.agents})
    observations, *_ = env.step({})
    view = env._run.view()
    spaces = env.spaces
    lay = spaces.layout()
    rho = 425 * math.tan(math.radians(5))
    for i in range(5):
        o = observations[f"uav_{i}"]
        assert o.dtype == np.float32 and env.observation_space(f"uav_{i}").contains(o)
        x, y, _, V, psi = view.believed[0, i]
        own = dict(zip(OWN, o[lay["own"]], strict=True))
        assert own["alive"] == 1 and own["progress"] == pytest.approx(2 / 10)
        assert own["cos_heading"] == pytest.approx(math.cos(psi), abs=1e-6)
        assert own["x"] == pytest.approx((x - 100) / 100, abs=1e-5)
        rows = o[lay["targets"]].reshape(4, len(TARGET))
        # each row gives back an estimate's position: bearing in the heading frame, distance
        got = []
        for row in rows:
            r = dict(zip(TARGET, row, strict=True))
            d = rho * math.expm1(r["distance"])
            b = math.atan2(r["sin_bearing"], r["cos_bearing"])
            got.append((x + d * math.cos(psi + b), y + d * math.sin(psi + b)))
        estimates = view.mean[0, i, :, :2]
        order = np.argsort(np.hypot(*(estimates - [x, y]).T), kind="stable")
        assert np.allclose(got, estimates[order], atol=1e-3 * rho * 10)
        # nearest first
        assert np.all(np.diff(rows[:, TARGET.index("distance")]) >= 0)
        neighbours = o[lay["neighbours"]].reshape(4, len(NEIGHBOUR))
        others = np.delete(view.links[0, i], i)
        assert neighbours[:, 0].sum() == others.sum()  # the UAVs in radio range


def test_dict_observations_hold_what_the_uav_knows():
    env = parallel_env(steps=10, observation="dict")
    observations, infos = env.reset(seed=7)
    for a in env.agents:
        assert env.observation_space(a).contains(observations[a])
    observations, *_ = env.step({a: infos[a]["paper_action"] for a in env.agents})
    pending = env._run.pending
    o = observations["uav_2"]
    assert np.array_equal(o["estimates"], pending.fused.mean[0, 2])
    assert o["covariance"][1, 2] == pending.fused.cov[0, 2, 1, 0, 1]


def test_state_is_the_teams_best_view():
    env = parallel_env(steps=10)
    env.reset(seed=1)
    env.step({})
    state = env.state()
    view = env._run.view()
    assert env.state_space.contains(state) and state[0] == pytest.approx(0.1)
    trace = np.trace(view.cov[0], axis1=-2, axis2=-1)  # (Nu, Nt)
    best = view.mean[0, trace.argmin(axis=0), np.arange(4)]  # the most confident UAV's
    rows = state[1 + 5 * 7 :].reshape(4, 7)
    assert np.allclose(rows[:, 1], (best[:, 0] - 100) / 100, atol=1e-5)
    assert np.allclose(rows[:, 4], best[:, 3] / 15, atol=1e-5)
    assert np.array_equal(rows[:, 6], view.observed[0].any(axis=0))


def test_max_targets_and_neighbours_cap_the_rows():
    env = parallel_env(steps=5, max_targets=2, max_neighbours=1)
    observations, _ = env.reset(seed=0)
    assert observations["uav_0"].shape == (len(OWN) + 2 * len(TARGET) + len(NEIGHBOUR),)
    with pytest.raises(ValueError, match="max_targets must be in"):
        parallel_env(max_targets=5)


# ---------------------------------------------------------------- faults


def test_a_failed_uav_terminates_as_an_agent():
    env = parallel_env(steps=30, faults={"failures": [[1, 10]]})
    observations, infos = env.reset(seed=0)
    gone_at = None
    while env.agents:
        observations, rewards, terminations, truncations, infos = env.step(
            {a: infos[a]["paper_action"] for a in env.agents}
        )
        if terminations.get("uav_1") and not truncations["uav_1"]:
            gone_at = env.result().trace.observed.shape[0]
            assert not observations["uav_1"].any()  # it observes nothing any more
        if not any(truncations.values()):
            assert not any(terminations[a] for a in terminations if a != "uav_1")
    assert gone_at == 10 and "uav_1" not in env.agents


def test_actions_for_a_failed_uav_are_ignored():
    # PettingZoo's convention (its conversions step only env.agents): a wrapper that keeps
    # every possible agent, as TorchRL's does, sends actions for the failed UAV too
    told, left = (parallel_env(steps=8, faults={"failures": [[1, 3]]}) for _ in range(2))
    told.reset(seed=4)
    left.reset(seed=4)
    for k in range(8):
        a = told.step({agent: 0 for agent in told.possible_agents})
        b = left.step({agent: 0 for agent in left.agents})
        assert a[0].keys() == b[0].keys() and a[1] == pytest.approx(b[1], rel=1e-12)
        for agent in a[0]:
            np.testing.assert_allclose(a[0][agent], b[0][agent], rtol=1e-12)
        assert ("uav_1" in told.agents) == (k < 2)
    assert not told.agents  # a name never an agent stays refused (test_bad_input_is_named)


def test_the_missions_end_terminates_and_truncates_every_agent():
    env = parallel_env(steps=3)
    env.reset(seed=0)
    for _ in range(3):
        observations, rewards, terminations, truncations, infos = env.step({})
    assert all(terminations.values()) and all(truncations.values()) and not env.agents
    assert set(rewards.values()) == {0.0}  # nothing follows the last cycle


# ---------------------------------------------------------------- PettingZoo's tests


def test_pettingzoo_parallel_and_aec_api():
    parallel_api_test(parallel_env(steps=20), num_cycles=30)
    api_test(uavenv.env(steps=20), num_cycles=30)
    api_test(uavenv.env(steps=20, faults={"failures": [[2, 5]]}), num_cycles=30)


def test_pettingzoo_seed_tests():
    parallel_seed_test(lambda: parallel_env(steps=25), num_cycles=30)
    seed_test(lambda: uavenv.env(steps=25), num_cycles=30)


def test_pettingzoo_max_cycles_test():
    max_cycles_test(uavenv)


def test_pettingzoo_state_test_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NaN, no infinity, no zeros, the right shapes
        state_test(uavenv.env(steps=20), parallel_env(steps=20), num_cycles=25)


def test_pettingzoo_render_test_every_declared_mode(monkeypatch):
    import matplotlib.pyplot as plt

    monkeypatch.setattr(plt, "pause", lambda seconds: None)  # no window to wait for
    render_test(lambda render_mode=None: uavenv.env(steps=6, render_mode=render_mode))
    env = parallel_env(steps=5, render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="reset"):
        env.render()
    env.reset(seed=0)
    assert env.render().shape == (800, 1000, 3)  # the first cycle, before any step
    env.step({})
    frame = env.render()
    assert frame.shape == (800, 1000, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # something is drawn
    text = parallel_env(steps=5, render_mode="ansi")
    text.reset(seed=0)
    assert text.render().startswith("step 0/5 in view ")


# ---------------------------------------------------------------- misuse


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="render_mode"):
        parallel_env(render_mode="video")
    with pytest.raises(ValueError, match="reward must be one of"):
        parallel_env(reward="speed")
    with pytest.raises(ValueError, match="observation must be one of"):
        parallel_env(observation="image")
    with pytest.raises(ValueError, match="max_cycles or steps"):
        parallel_env(max_cycles=5, steps=5)
    env = parallel_env(steps=5)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not in Discrete"):
        env.step({"uav_0": 3})
    with pytest.raises(ValueError, match="unknown agent"):
        env.step({"uav_9": 1})
    with pytest.raises(ValueError, match="unknown agent"):
        env.observation_space("uav_9")
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        env.reset(seed=-1)
    with pytest.raises(uavtrack.ScenarioError, match="steps"):
        parallel_env(steps=0)
    with pytest.raises(uavtrack.ScenarioError, match="steps"):
        parallel_env(max_cycles=0)


def test_a_scenario_too_large_is_refused_when_the_env_is_made():
    huge = uavtrack.Scenario().scaled(1000, 1000).with_overrides({"steps": 20000})
    with pytest.raises(uavtrack.ScenarioError, match="of memory"):
        parallel_env(huge)
    with pytest.raises(uavtrack.ScenarioError, match="of memory"):
        uavenv.vector_env(4096, uavtrack.Scenario().scaled(200, 200))


def test_misuse_gets_a_clear_error():
    env = parallel_env(steps=5)
    with pytest.raises(RuntimeError, match=r"call reset\(\) and step\(\) before result"):
        env.result()
    with pytest.raises(RuntimeError, match=r"call reset\(\) before state"):
        env.state()
    env.reset(seed=0)
    with pytest.raises(RuntimeError, match="no step flown yet"):
        env.result()
    with pytest.raises(TypeError, match="actions must be a dict"):
        env.step(None)
    while env.agents:
        env.step({})
    with pytest.raises(RuntimeError, match="episode is over"):
        env.step({})


def test_the_benchmarl_task_without_benchmarl_says_how_to_install_it(monkeypatch):
    for name in [m for m in sys.modules if m.startswith("benchmarl.")]:
        monkeypatch.delitem(sys.modules, name)  # loaded by an earlier test
    monkeypatch.setitem(sys.modules, "benchmarl", None)  # as if not installed
    monkeypatch.delitem(sys.modules, "uavtrack.env.benchmarl", raising=False)
    with pytest.raises(ImportError, match=r"needs benchmarl: pip install .*benchmarl"):
        importlib.import_module("uavtrack.env.benchmarl")
