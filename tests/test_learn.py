"""The environment in the learning libraries' own hands (the learn extra: torch,
Stable-Baselines3, SuperSuit, TorchRL, BenchMARL); skipped where they are not installed."""

import numpy as np
import pytest

pytest.importorskip("pettingzoo")
torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")
ss = pytest.importorskip("supersuit")
pytest.importorskip("torchrl")
pytest.importorskip("benchmarl")

from benchmarl.experiment.callback import Callback  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from torchrl.envs.libs.pettingzoo import PettingZooWrapper  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

from uavtrack import ScenarioError  # noqa: E402
from uavtrack.env import parallel_env, vector_env  # noqa: E402
from uavtrack.env.benchmarl import UAVTrackTask  # noqa: E402
from uavtrack.env.learn import sb3_vec_env, torchrl_env  # noqa: E402

FAILING = {"faults": {"failures": [[1, 4]]}}


def test_torchrl_check_env_specs_with_state():
    env = torchrl_env(vector_env(3, steps=6, **FAILING), seed=0)
    check_env_specs(env)
    rollout = env.rollout(13, break_when_any_done=False)  # two episodes and a bit
    done = rollout["next", "done"][:, :, 0]  # (trials, steps)
    assert done[:, 5].all() and done[:, 11].all() and done.sum() == 2 * 3
    state = rollout["next", "state"]
    assert state.shape == (3, 13, env.vector.state_space.shape[0])
    alive = rollout["next", "agents", "alive"][..., 0]
    assert not alive[:, 4, 1].any() and alive[:, 4, 0].all()  # UAV 1 fails at step 4
    assert not rollout["next", "agents", "observation"][:, 4, 1].any()  # and sees nothing


def test_torchrl_pettingzoo_wrapper_with_state():
    env = PettingZooWrapper(parallel_env(steps=8), return_state=True, use_mask=True)
    check_env_specs(env)
    assert env.rollout(5)["state"].shape[-1] == parallel_env().state_space.shape[0]


def test_torchrl_pettingzoo_wrapper_flies_on_past_a_failure():
    # TorchRL sends an action for every possible agent, the failed one's included; with
    # done_on_any=False the episode is over only when every agent is
    failing = parallel_env(steps=10, **FAILING)
    env = PettingZooWrapper(failing, return_state=True, use_mask=True, done_on_any=False)
    check_env_specs(env)
    rollout = env.rollout(30, auto_reset=False, tensordict=env.reset(seed=5))
    assert rollout.batch_size == (10,)  # the mission's 10 steps, not 4
    done = rollout["next", "uav", "done"][..., 0]
    assert not done[:3].any() and done[3:, 1].all()  # UAV 1 is gone after 4 steps
    assert not done[:-1, [0, 2, 3, 4]].any() and done[-1].all()  # the others fly on
    assert rollout["next", "done"][:, 0].tolist() == [False] * 9 + [True]
    assert not rollout["next", "uav", "mask"][3:, 1].any()
    # the flown trial is parallel_env's, reward for reward
    single = parallel_env(steps=10, **FAILING)
    single.reset(seed=5)
    for k, chosen in enumerate(rollout["uav", "action"].tolist()):
        acting = {a: chosen[i] for i, a in enumerate(single.possible_agents) if a in single.agents}
        _, rewards, *_ = single.step(acting)
        got = rollout["next", "uav", "reward"][k, :, 0].tolist()
        want = [rewards.get(f"uav_{i}", 0.0) for i in range(5)]
        assert got == pytest.approx(want, rel=1e-6)  # float32 in TorchRL
    assert not single.agents


def test_supersuit_black_death_keeps_failed_uavs_through_episodes():
    env = ss.black_death_v3(parallel_env(steps=6, **FAILING))
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class="stable_baselines3")
    observations = vec.reset()
    assert observations.shape == (10, env.observation_space("uav_0").shape[0])
    ends = 0
    for k in range(13):
        observations, rewards, dones, infos = vec.step(np.ones(10, dtype=np.int64))
        if k % 6 >= 4 and not dones.any():  # UAV 1 of each copy has failed: black death
            assert not observations[[1, 6]].any() and not rewards[[1, 6]].any()
        ends += dones.all()
    assert ends == 2  # both episodes ended and reset
    PPO("MlpPolicy", vec, n_steps=12, batch_size=60, n_epochs=1).learn(120)  # no seed():
    # SuperSuit's SB3 wrapper has none to pass one on


def test_sb3_vec_env_ends_episodes_as_terminal_states():
    vec = sb3_vec_env(vector_env(2, steps=5), seed=3)
    observations = vec.reset()
    assert observations.shape == (10, vec.observation_space.shape[0])
    for _ in range(5):
        observations, rewards, dones, infos = vec.step(np.full(10, 2))
    assert dones.all() and infos[0]["TimeLimit.truncated"] is False
    assert infos[7]["terminal_observation"].shape == observations[7].shape
    model = PPO("MlpPolicy", vec, n_steps=5, batch_size=50, n_epochs=1, seed=0)
    model.learn(100)
    assert model.num_timesteps == 100


TRACKED = {
    "tracker": {"association": "jpda"},
    "sensor": {"detection_probability": 0.9, "clutter_rate": 2},
}


def test_tracked_scenarios_in_torchrl_and_sb3():
    check_env_specs(torchrl_env(vector_env(2, steps=5, **TRACKED), seed=0))
    env = torchrl_env(vector_env(2, steps=5, **TRACKED), seed=0)
    rollout = env.rollout(5, break_when_any_done=False)
    assert rollout["next", "done"][:, -1].all()
    # the rewards are vector_env's trials 0 and 1 flown with the same actions
    v = vector_env(2, steps=5, **TRACKED)
    v.reset(seed=0)
    for k in range(5):
        _, rewards, *_ = v.step(rollout["agents", "action"][:, k].numpy())
        got = rollout["next", "agents", "reward"][:, k, :, 0].numpy()
        np.testing.assert_allclose(got, rewards, rtol=1e-6)
    wrapped = PettingZooWrapper(parallel_env(steps=6, **TRACKED), return_state=True)
    check_env_specs(wrapped)
    vec = sb3_vec_env(vector_env(2, steps=4, **TRACKED), seed=1)
    model = PPO("MlpPolicy", vec, n_steps=4, batch_size=40, n_epochs=1, seed=0)
    model.learn(40)
    assert model.num_timesteps == 40


# ---------------------------------------------------------------- BenchMARL


def tiny_experiment(task, folder, callbacks=()):
    """One MAPPO iteration of 2 trials x 8 steps, small nets, CPU, nothing logged."""
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig

    config = ExperimentConfig.get_from_yaml()
    config.max_n_iters = 1
    config.max_n_frames = None
    config.on_policy_collected_frames_per_batch = 16
    config.on_policy_n_envs_per_worker = 2
    config.on_policy_n_minibatch_iters = 2
    config.on_policy_minibatch_size = 8
    config.lr = 1e-3
    config.evaluation, config.render, config.loggers = False, False, []
    config.create_json, config.save_folder = False, str(folder)
    model = MlpConfig.get_from_yaml()
    model.num_cells = [16]
    return Experiment(
        task=task,
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=model,
        critic_model_config=model,
        seed=0,
        config=config,
        callbacks=list(callbacks),
    )


class Seen(Callback):
    """Keeps what an experiment collected and its training losses (a module's class:
    BenchMARL pickles its callbacks)."""

    def __init__(self):
        super().__init__()
        self.batches, self.losses = [], []

    def on_batch_collected(self, batch):
        self.batches.append(batch.clone())

    def on_train_end(self, training_td, group):
        self.losses.append(training_td.clone())


def test_benchmarl_mappo_trains_one_iteration_on_the_task(tmp_path):
    seen = Seen()
    overrides = {"steps": 8, **FAILING}
    task = UAVTrackTask.TRACKING.get_task({"overrides": overrides})
    experiment = tiny_experiment(task, tmp_path, [seen])
    before = [p.detach().clone() for p in experiment.policy.parameters()]
    experiment.run()
    assert experiment.n_iters_performed == 1 and experiment.total_frames == 16
    (batch,) = seen.batches
    assert batch.batch_size == (2, 8)  # two trials of the mission's 8 steps
    assert batch["next", "done"][:, :, 0].tolist() == [[False] * 7 + [True]] * 2
    observation = batch["next", "agents", "observation"]
    assert observation.shape[2] == 5 and not observation[:, 3:, 1].any()  # UAV 1 is down
    assert observation[:, 3:, 0].any()
    # the trials BenchMARL played are vector_env's trials 0 and 1, reward for reward
    v = vector_env(2, paper_actions=False, **overrides)
    v.reset(seed=0)
    for k in range(8):
        _, rewards, *_ = v.step(batch["agents", "action"][:, k].numpy())
        got = batch["next", "agents", "reward"][:, k, :, 0].numpy()
        np.testing.assert_allclose(got, rewards, rtol=1e-6)
    # MAPPO trained: finite losses, and the shared policy moved
    (losses,) = seen.losses
    for key in ("loss_objective", "loss_critic", "loss_entropy"):
        assert torch.isfinite(losses[key]).all()
    after = list(experiment.policy.parameters())
    assert any(not torch.equal(a, b.detach()) for a, b in zip(before, after, strict=True))


def test_benchmarl_task_names_a_bad_setting():
    with pytest.raises(ValueError, match=r"unknown uavtrack task settings \['rewrad'\]"):
        UAVTrackTask.TRACKING.get_task({"rewrad": "team"})
    with pytest.raises(ScenarioError, match="steps"):
        UAVTrackTask.TRACKING.get_task({"overrides": {"steps": 0}})
    with pytest.raises(ValueError, match="reward must be one of"):
        UAVTrackTask.TRACKING.get_task({"reward": "speed"})
    task = UAVTrackTask.TRACKING.get_task()  # the defaults: the paper's scenario
    assert task.max_steps(None) == 500 and task.group_map(None)["agents"][-1] == "uav_4"


def test_benchmarl_task_reads_its_settings_from_yaml(tmp_path):
    path = tmp_path / "task.yaml"
    path.write_text("reward: difference\noverrides:\n  steps: 7\n  n_uavs: 3\n")
    task = UAVTrackTask.TRACKING.get_from_yaml(str(path))
    assert task.config["reward"] == "difference" and task.max_steps(None) == 7
    assert task.group_map(None) == {"agents": ["uav_0", "uav_1", "uav_2"]}
    path.write_text("- reward\n")
    with pytest.raises(ValueError, match="must be a mapping"):
        UAVTrackTask.TRACKING.get_from_yaml(str(path))


# ---------------------------------------------------------------- the MARL rows


@pytest.mark.parametrize("row", ["mappo", "ippo", "mappo-gnn"])
def test_a_marl_rows_policy_file_is_its_benchmarl_actor(tmp_path, row):
    """The policy file of a BenchMARL row computes the logits of BenchMARL's own actor
    (a graph row's GraphConv included) on what its rollouts observed: the rates the
    file flies are the actor's."""
    pytest.importorskip("torch_geometric")
    from uavtrack import Scenario
    from uavtrack.env.spaces import Spaces
    from uavtrack.experiments import learned

    scenario = Scenario(steps=20)
    settings = learned.Marl(frames=400, batch=400, trials=2, hidden=16)
    run = learned.marl_experiment(scenario, row, settings, 0, str(tmp_path))
    run.run()
    policy = learned.policy_of(run, row, settings)
    assert (policy.graph is not None) == (row == "mappo-gnn")
    rollout = run.env_func().rollout(25, policy=run.policy, break_when_any_done=False)
    with torch.no_grad():
        logits = run.policy(rollout.clone())["agents", "logits"].numpy()
    observation = rollout["agents", "observation"].numpy()
    mine = policy.logits(observation, Spaces(scenario, "box", 4, 4))
    np.testing.assert_allclose(mine, logits, rtol=1e-4, atol=1e-5)
    assert (np.argmax(mine, -1) == np.argmax(logits, -1)).all()


def test_the_dense_radius_graph_links_exactly_the_pairs_in_range():
    from uavtrack.env.benchmarl import dense_radius_graph

    rng = np.random.default_rng(0)
    x = torch.as_tensor(rng.uniform(0, 3, (4 * 6, 3)), dtype=torch.float32)
    batch = torch.repeat_interleave(torch.arange(4), 6)
    edges = dense_radius_graph(x, 1.5, batch).numpy()
    got = set(map(tuple, edges.T.tolist()))
    want = {
        (j, i)
        for i in range(24)
        for j in range(24)
        if i != j and i // 6 == j // 6 and np.linalg.norm(x[i] - x[j]) <= 1.5
    }
    assert got == want and 0 < len(want) < 24 * 5
    with_loops = dense_radius_graph(x, 1.5, batch, loop=True).numpy()
    assert with_loops.shape[1] == len(want) + 24
