"""The PettingZoo environment: the simulator's own cycle, the agents' actions."""

import numpy as np
import pytest

import uavtrack
from uavtrack.equivalence import assert_same_trace

pytest.importorskip("pettingzoo")
from pettingzoo.test import parallel_api_test  # noqa: E402

from uavtrack.env import parallel_env  # noqa: E402


def fly(env, policy, seed):
    observations, infos = env.reset(seed=seed)
    total = {a: 0.0 for a in env.possible_agents}
    while env.agents:
        actions = {a: policy(a, observations[a], infos[a]) for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        for a, r in rewards.items():
            total[a] += r
    return total


@pytest.mark.parametrize("method", ["distributed", "centralized", "greedy"])
def test_paper_actions_through_the_env_are_simulate(method):
    env = parallel_env(method_for_others=method, steps=50)
    fly(env, lambda a, o, info: info["paper_action"], seed=4)
    ours = env.result()
    reference = uavtrack.simulate(uavtrack.Scenario(steps=50), method, seed=4)
    assert_same_trace(ours.trace, reference.trace)
    for name in ("observation_rate", "rmse", "nees", "ospa_best", "messages"):
        assert getattr(ours, name) == getattr(reference, name)


def test_agents_left_out_fly_the_method():
    env = parallel_env(steps=30)
    fly(env, lambda a, o, info: info["paper_action"], seed=1)
    full = env.result()
    env.reset(seed=1)
    while env.agents:
        env.step({})  # nobody acts: every UAV flies the paper's method
    assert_same_trace(env.result().trace, full.trace)


def test_rewards_are_the_targets_each_uav_sees_next():
    env = parallel_env(steps=40)
    total = fly(env, lambda a, o, info: info["paper_action"], seed=2)
    trace = env.result().trace
    seen = trace.observed[1:].sum(axis=(0, 2))  # cycles 1 .. T-1, per UAV
    assert [total[f"uav_{i}"] for i in range(5)] == seen.tolist()


def test_other_actions_change_the_flight_not_the_stages():
    env = parallel_env(steps=25)
    fly(env, lambda a, o, info: 1, seed=0)  # everybody straight
    trace = env.result().trace
    assert np.all(trace.action == 0.0)
    headings = trace.uavs[..., 4]
    assert np.allclose(headings, headings[0])  # nobody turns
    assert trace.observed.shape == (25, 5, 4)


def test_observations_hold_what_the_uav_knows():
    env = parallel_env(steps=10)
    observations, infos = env.reset(seed=7)
    space = env.observation_space("uav_0")
    for a in env.agents:
        assert space.contains(observations[a])
    env.step({a: infos[a]["paper_action"] for a in env.agents})
    pending = env._pending  # the cycle the next observation comes from
    o = env._observations()["uav_2"]
    assert np.array_equal(o["estimates"], pending.fused.mean[0, 2])
    assert o["covariance"][1, 2] == pending.fused.cov[0, 2, 1, 0, 1]


def test_a_failed_uav_terminates_as_an_agent():
    env = parallel_env(steps=30, faults={"failures": [[1, 10]]})
    observations, infos = env.reset(seed=0)
    gone_at = None
    while env.agents:
        observations, rewards, terminations, truncations, infos = env.step(
            {a: infos[a]["paper_action"] for a in env.agents}
        )
        if terminations.get("uav_1"):
            gone_at = env.result().trace.observed.shape[0]
        assert not any(terminations[a] for a in terminations if a != "uav_1")
    assert gone_at == 10 and "uav_1" not in env.agents


def test_pettingzoo_api_and_render():
    parallel_api_test(parallel_env(steps=20), num_cycles=30)
    env = parallel_env(steps=5, render_mode="rgb_array")
    with pytest.raises(RuntimeError, match="reset"):
        env.render()
    env.reset(seed=0)
    assert env.render().shape == (800, 1000, 3)  # the first cycle, before any step
    env.step({})
    frame = env.render()
    assert frame.shape == (800, 1000, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # something is drawn


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="render_mode"):
        parallel_env(render_mode="human")
    env = parallel_env(steps=5)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not in Discrete"):
        env.step({"uav_0": 3})
    with pytest.raises(ValueError, match="unknown agent"):
        env.step({"uav_9": 1})
    with pytest.raises(uavtrack.ScenarioError, match="steps"):
        parallel_env(steps=0)


def test_a_scenario_too_large_is_refused_when_the_env_is_made():
    from uavtrack.config import ScenarioError

    huge = uavtrack.Scenario().scaled(1000, 1000).with_overrides({"steps": 20000})
    with pytest.raises(ScenarioError, match="of memory"):
        parallel_env(huge)


def test_misuse_gets_a_clear_error():
    env = parallel_env(steps=5)
    with pytest.raises(RuntimeError, match=r"call reset\(\) and step\(\) before result"):
        env.result()
    env.reset(seed=0)
    with pytest.raises(TypeError, match="actions must be a dict"):
        env.step(None)


def test_changing_an_observation_changes_nothing_of_the_trial():
    # a common normalisation, done in place on what the env handed out
    def meddle(a, o, info):
        o["estimates"][:, :2] -= o["uav"][:2]
        o["uav"][:] = 0.0
        return info["paper_action"]

    env = parallel_env(steps=30)
    fly(env, meddle, seed=2)
    reference = uavtrack.simulate(uavtrack.Scenario(steps=30), "distributed", seed=2)
    assert_same_trace(env.result().trace, reference.trace)
