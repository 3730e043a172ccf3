"""The single-agent Gymnasium Env: one UAV learns, the team flies on; Gymnasium's own
checker and registry."""

import warnings

import numpy as np
import pytest

import uavtrack
from uavtrack.testing import assert_same_trace

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("pettingzoo")
from gymnasium.utils.env_checker import check_env  # noqa: E402

from uavtrack.env import ID, SingleUAVEnv  # noqa: E402


def fly(env, choose, seed=None):
    """One episode; returns (rewards, terminated, truncated) of its steps."""
    observation, info = env.reset(seed=seed)
    out = []
    while True:
        observation, reward, terminated, truncated, info = env.step(choose(observation, info))
        out.append((reward, terminated, truncated))
        if terminated or truncated:
            return out


def test_gymnasium_checks_the_env_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gymnasium.make(ID, max_cycles=12).unwrapped)
    # the raw Dict form's unbounded boxes draw Gymnasium's warnings, not its errors
    check_env(gymnasium.make(ID, max_cycles=12, observation="dict", learner=3).unwrapped)


def test_the_id_makes_it_with_gymnasiums_wrappers():
    made = gymnasium.make(ID, max_cycles=10, learner=2)
    assert isinstance(made.unwrapped, SingleUAVEnv) and made.unwrapped.name == "uav_2"
    assert made.spec is not None and made.spec.id == "uavtrack/SingleUAV-v0"
    steps = fly(made, lambda o, i: i["paper_action"], seed=1)
    assert len(steps) == 10 and steps[-1][1:] == (True, True)
    assert not any(t or u for _, t, u in steps[:-1])


@pytest.mark.parametrize("learner", [0, 4])
def test_flying_the_paper_action_reproduces_simulate(learner):
    env = SingleUAVEnv(max_cycles=25, learner=learner)
    rewards = fly(env, lambda o, i: i["paper_action"], seed=3)
    reference = uavtrack.simulate(uavtrack.Scenario(steps=25), seed=3)
    assert_same_trace(env.result().trace, reference.trace)
    # the team reward: its mean is the observation rate, less the first step's
    seen = reference.trace.observed.any(axis=1).mean(axis=1)  # (T,)
    np.testing.assert_allclose([r for r, _, _ in rewards], seen[1:].tolist() + [0.0])


def test_the_others_fly_a_given_policy_and_the_learner_its_own():
    env = SingleUAVEnv(max_cycles=15, learner=1, others=lambda observation: 1)  # straight
    fly(env, lambda o, i: 2, seed=0)  # the learner circles
    action = env.result().trace.action  # (T, N) bank angles
    assert (action[:, 1] > 0).all()
    assert (action[:, [0, 2, 3, 4]] == 0).all()


def test_the_learners_failure_ends_its_episode():
    env = SingleUAVEnv(max_cycles=20, learner=1, faults={"failures": [[1, 6]]})
    steps = fly(env, lambda o, i: i["paper_action"], seed=0)
    assert len(steps) < 20
    assert steps[-1][1] and not steps[-1][2]  # terminated, not truncated
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(1)


def test_a_learner_failed_at_the_start_is_refused_by_seed_and_redrawn_without():
    env = SingleUAVEnv(max_cycles=8, learner=1, faults={"failure_rate": 0.3})
    dead = [s for s in range(30) if "uav_1" not in env.team.reset(seed=s)[0]]
    assert dead  # some trials fail the learner before the first cycle
    with pytest.raises(ValueError, match="has failed at step 0 of trial") as info:
        env.reset(seed=dead[0])
    assert "\n" not in str(info.value)
    env.reset(seed=min(set(range(30)) - set(dead)))  # seeds the Env's own stream
    for _ in range(10):  # each draws a trial in which the learner flies
        observation, info_ = env.reset()
        assert env.observation_space.contains(observation) and "paper_action" in info_
        env.step(1)


def test_a_seedless_reset_draws_from_the_envs_own_stream():
    one, two = SingleUAVEnv(max_cycles=5), SingleUAVEnv(max_cycles=5)
    one.reset(seed=7)
    two.reset(seed=7)
    first = [one.reset()[0] for _ in range(3)]
    second = [two.reset()[0] for _ in range(3)]
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], first[1])


def test_bad_arguments_are_refused_in_one_line():
    for kwargs, error, named in (
        ({"learner": 5}, ValueError, "learner 5 is not a UAV: give 0 to 4"),
        ({"learner": "uav_0"}, TypeError, "learner must be a UAV index"),
        ({"others": 3}, TypeError, "others must be a policy"),
        ({"steps": -1}, uavtrack.ScenarioError, "steps"),
    ):
        with pytest.raises(error, match=named) as info:
            SingleUAVEnv(**kwargs)
        assert "\n" not in str(info.value)
    env = SingleUAVEnv(max_cycles=5)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not in Discrete"):
        env.step(3)


def test_the_single_uav_ppo_example_trains_and_scores(monkeypatch, capsys):
    """examples/single_ppo.py, the docs' few lines of PPO on ``uavtrack/SingleUAV-v0``,
    in a smoke run: it trains, and the paper's method it is compared with scores as
    ``simulate`` does. Needs the learn extra (torch, Stable-Baselines3)."""
    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    import importlib.util
    from pathlib import Path

    path = Path(__file__).parents[1] / "examples" / "single_ppo.py"
    spec = importlib.util.spec_from_file_location("single_ppo", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    scores = module.main(["--steps", "256", "--trials", "2"])
    seeds = [module.HELD_OUT, module.HELD_OUT + 1]
    scenario = uavtrack.Scenario(steps=module.CYCLES)
    rates = [uavtrack.simulate(scenario, seed=s).observation_rate for s in seeds]
    assert scores["paper"][1] == pytest.approx(np.mean(rates))
    assert 0.0 <= scores["ppo"][1] <= 1.0
    assert "observation rate" in capsys.readouterr().out
