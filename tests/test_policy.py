"""A learned policy as a decision method (`uavtrack.env.policy`) and the imitation of the
paper's planner that makes one (`uavtrack.experiments.learned`): the file, the cycle it flies, the
commands that take it, and what the imitation learns."""

import json
from dataclasses import replace

import numpy as np
import pytest

import uavtrack

pytest.importorskip("gymnasium")
from uavtrack import cli, simulation  # noqa: E402
from uavtrack.env.episodes import Episodes  # noqa: E402
from uavtrack.env.policy import Policy, PolicyMethod  # noqa: E402
from uavtrack.env.spaces import OWN, TARGET, Spaces  # noqa: E402
from uavtrack.errors import UsageError  # noqa: E402
from uavtrack.experiments import learned  # noqa: E402
from uavtrack.methods import get  # noqa: E402
from uavtrack.testing import assert_same_trace  # noqa: E402

SHORT = uavtrack.Scenario().with_overrides({"steps": 40})
SIZE = Spaces(SHORT, "box", 4, 4).size


def random_policy(seed=0, hidden=16, size=SIZE):
    rng = np.random.default_rng(seed)
    return Policy(
        layers=[
            (rng.normal(0, 0.5, (size, hidden)).astype(np.float32), rng.normal(0, 0.1, hidden)),
            (rng.normal(0, 1.0, (hidden, 3)).astype(np.float32), rng.normal(0, 0.1, 3)),
        ],
        meta={"row": "test"},
    )


def pursuit():
    """A one-layer policy that turns toward its nearest target's estimate (+phi turns
    left, toward a positive sine of the bearing) and flies straight when it is ahead."""
    W = np.zeros((SIZE, 3), dtype=np.float32)
    sine = len(OWN) + TARGET.index("sin_bearing")  # the nearest target's row comes first
    W[sine, 0], W[sine, 2] = -10.0, 10.0
    return Policy(layers=[(W, np.array([0.0, 1.0, 0.0], dtype=np.float32))])


def constant(action, size=SIZE):
    bias = np.zeros(3, dtype=np.float32)
    bias[action] = 1.0
    return Policy(layers=[(np.zeros((size, 3), dtype=np.float32), bias)])


def test_a_policy_file_round_trips_and_computes_its_perceptron(tmp_path):
    policy = random_policy()
    loaded = Policy.load(policy.save(tmp_path / "p.npz"))
    assert loaded.meta["row"] == "test" and loaded.inputs == SIZE
    x = np.random.default_rng(1).normal(size=(7, SIZE)).astype(np.float32)
    (W0, b0), (W1, b1) = policy.layers
    expected = np.tanh(x.astype(np.float64) @ W0 + b0) @ W1 + b1
    np.testing.assert_allclose(loaded.logits(x), expected, rtol=1e-4, atol=1e-4)
    np.testing.assert_array_equal(loaded.act(x), np.argmax(expected, axis=-1))
    tie = Policy(layers=[(np.zeros((SIZE, 3), dtype=np.float32), np.zeros(3, dtype=np.float32))])
    assert (tie.act(x) == 0).all()  # the lowest index on ties
    assert not list(tmp_path.glob("*.part"))


def test_flying_a_policy_is_the_environment_flying_its_actions(tmp_path):
    """A policy that always flies straight gives the trace of the environment's own loop
    (no planning) told to fly straight every step: the same cycle, step for step, but
    the beacons of whole states the policy's UAVs send, one message a link, all of
    them delivered on the fault-free radio."""
    path = constant(1).save(tmp_path / "straight.npz")
    flown = uavtrack.run(SHORT, f"policy:{path}", seeds=[3], trace=True)
    episodes = Episodes(
        SHORT, get("distributed"), Spaces(SHORT), "team", [np.random.SeedSequence(3)],
        record=True, plan=False,
    )  # fmt: skip
    while not episodes.done:
        episodes.step(np.ones((1, SHORT.n_uavs), dtype=np.int64))
    alone = episodes.batch_result()
    assert flown.traces is not None and alone.traces is not None
    f, a = flown.traces[0], alone.traces[0]
    assert_same_trace(f, a, counters=False)
    for name in ("rounds", "late", "node_bytes", "conflicts"):
        np.testing.assert_array_equal(getattr(f, name), getattr(a, name), err_msg=name)
    links = simulation.graph(np.asarray(f.uavs), np.asarray(f.alive), SHORT)
    beacons = (links & ~np.eye(SHORT.n_uavs, dtype=bool)).sum(axis=(1, 2))
    assert beacons.max() > 0 and beacons.min() == 0  # steps with beacons, and without
    np.testing.assert_array_equal(np.asarray(f.messages) - np.asarray(a.messages), beacons)
    np.testing.assert_array_equal(np.asarray(f.delivered) - np.asarray(a.delivered), beacons)
    sent = links.any(axis=1)  # a UAV with a receiver in range puts its beacon on air
    assert (np.asarray(f.bytes)[sent] > np.asarray(a.bytes)[sent]).all()
    assert (np.asarray(f.bytes)[~sent] == np.asarray(a.bytes)[~sent]).all()
    assert (np.asarray(f.action) == 0.0).all()  # straight: bank 0
    assert flown.metrics["observation_rate"] == pytest.approx(alone.metrics["observation_rate"])
    assert np.isnan(np.asarray(flown.traces[0].bids)).all()  # no planner, no bids


def test_a_policy_flies_each_trial_of_a_batch_as_alone(tmp_path):
    path = pursuit().save(tmp_path / "pursuit.npz")
    batch = uavtrack.run(SHORT, f"policy:{path}", seeds=[0, 1, 2]).metrics["observation_rate"]
    alone = [uavtrack.run(SHORT, f"policy:{path}", seeds=[s]).metrics["observation_rate"][0]
             for s in (0, 1, 2)]  # fmt: skip
    np.testing.assert_allclose(batch, alone)


def test_a_policy_that_pursues_its_nearest_target_steers_and_sees_more_than_straight(
    tmp_path,
):
    scenario = SHORT.with_overrides({"steps": 150})
    seeds = list(range(6))
    chased = uavtrack.run(scenario, f"policy:{pursuit().save(tmp_path / 'p.npz')}", seeds,
                          trace=True)  # fmt: skip
    straight = uavtrack.run(scenario, f"policy:{constant(1).save(tmp_path / 's.npz')}", seeds)
    assert chased.traces is not None
    assert len(np.unique(np.asarray(chased.traces[0].action))) == 3  # it steers every way
    rate = chased.metrics["observation_rate"].mean()
    assert rate > straight.metrics["observation_rate"].mean() + 0.1


def test_a_policy_that_does_not_fit_is_refused_in_one_line(tmp_path):
    (tmp_path / "text.npz").write_text("not an archive")
    for spec, named in (
        (tmp_path / "missing.npz", "no policy file"),
        (tmp_path / "text.npz", "is not a policy file"),
    ):
        with pytest.raises(UsageError, match=named):
            Policy.load(spec)
    small = constant(1, size=SIZE - 1).save(tmp_path / "small.npz")
    with pytest.raises(UsageError, match=f"reads {SIZE - 1} numbers"):
        uavtrack.run(SHORT, f"policy:{small}")
    with pytest.raises(ValueError, match="logits"):
        Policy(layers=[(np.zeros((SIZE, 2), dtype=np.float32), np.zeros(2, dtype=np.float32))])
    bad = np.zeros((SIZE, 3), dtype=np.float32)
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        Policy(layers=[(bad, np.zeros(3, dtype=np.float32))])


def test_the_commands_take_a_policy_beside_the_paper_and_refuse_a_bad_one(tmp_path, capsys):
    path = random_policy().save(tmp_path / "p.npz")
    code = cli.main(["compare", "--method", "distributed", "--method", f"policy:{path}",
                     "--trials", "2", "--steps", "20", "--json"])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0, err
    assert f"policy:{path}" in json.loads(out)["methods"]
    code = cli.main(["sweep", "sensor.half_fov_deg", "20", "30", "--method", f"policy:{path}",
                     "--trials", "1", "--steps", "10", "--workers", "1",
                     "--out", str(tmp_path / "sweep")])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    capsys.readouterr()
    for argv, named in (
        (["run", "--method", f"policy:{tmp_path / 'none.npz'}"], "no policy file"),
        (["run", "--method", "polcy"], "policy:FILE"),
        (
            ["swarm", "--method", f"policy:{path}", "--set", 'tracker.association="jpda"'],
            "known association only",
        ),
    ):
        code = cli.main(argv)
        out, err = capsys.readouterr()
        assert code == 2, (argv, out, err)
        assert named in err and "Traceback" not in err


def test_the_method_is_named_after_its_file(tmp_path):
    path = constant(1).save(tmp_path / "straight.npz")
    method = get(f"policy:{path}")
    assert isinstance(method, PolicyMethod) and method.name == f"policy:{path}"
    assert not method.plans and get("distributed").plans


def test_the_perceptron_fit_separates_a_separable_labelling():
    """The NumPy fit (softmax cross-entropy, Adam) labels three separable clusters
    without error: its gradients point the right way."""
    rng = np.random.default_rng(0)
    centres = np.array([[-2.0, 0.0], [0.0, 2.0], [2.0, 0.0]])
    y = rng.integers(0, 3, 600)
    x = centres[y] + rng.normal(0, 0.3, (600, 2))
    settings = learned.Imitation(hidden=8, layers=1, epochs=30, batch=64, learning_rate=0.01)
    policy = learned._fit(x, y, settings, 0, lambda _: None)
    assert (policy.act(x) == y).mean() == 1.0


def test_dagger_learns_the_planners_choices_on_short_missions():
    """Two rounds of DAgger on missions of 100 steps: the policy picks the planner's
    action on states of trials it never saw far more often than the most common action's
    share (measured: 0.82 against 0.51)."""
    scenario = SHORT.with_overrides({"steps": 100})
    settings = learned.Imitation(rounds=2, trials=8, hidden=64, epochs=10)
    policy = learned.imitate(scenario, settings, seed=0, log=lambda _: None)
    assert policy.meta["row"] == "bc" and policy.meta["frames"] == 2 * 8 * 100 * 5
    assert len(policy.meta["round_rates"]) == len(policy.meta["round_losses"]) == 2
    x, y, _ = learned._collect(scenario, settings, policy, seed=5)  # other trials, it flies
    majority = np.bincount(y, minlength=3).max() / len(y)
    assert (policy.act(x) == y).mean() > majority + 0.15


@pytest.mark.parametrize(
    "name", ["bc", "bc-ppo", "bc-jpda", "bc-ppo-jpda", "mappo", "ippo", "mappo-gnn"]
)
def test_each_shipped_policy_reproduces_its_published_rates_on_its_first_trials(name):
    """A shipped policy flies its first three evaluation trials, on the scenario its file
    records, to the rates the file records (equal on the CPU that made it and on numpy's
    baseline path; within 0.05 a trial where another CPU's float32 sums could turn one
    close choice the other way)."""
    from uavtrack.env.policy import shipped
    from uavtrack.world import trial_seed

    assert name in shipped()
    evaluation = Policy.load(name).meta["evaluation"]
    assert evaluation["trials"] == 50
    scenario = uavtrack.Scenario.model_validate(evaluation["scenario"])
    seeds = [trial_seed(evaluation["seed"], t) for t in range(3)]
    got = uavtrack.run(scenario, f"policy:{name}", seeds).metrics["observation_rate"]
    np.testing.assert_allclose(got, evaluation["per_trial"]["policy"][:3], atol=0.05)


def test_one_command_trains_evaluates_and_reports_a_row(tmp_path, capsys):
    """``bc`` writes a policy file that carries its command and its evaluation (read back
    with NumPy and json alone), ``report`` makes its results page and figure, and bad
    input is one line with exit code 2 and no file."""
    import matplotlib.image

    out = tmp_path / "small.npz"
    argv = ["bc", "--rounds", "1", "--trials-per-round", "2", "--hidden", "8", "--epochs", "1",
            "--trials", "2", "--set", "steps=30", "--out", str(out)]  # fmt: skip
    assert learned.main(argv) == 0
    with np.load(out) as data:
        meta = json.loads(str(data["meta"]))
        assert data["W0"].shape == (SIZE, 8) and data["b2"].shape == (3,)
    assert meta["command"].endswith(" ".join(argv))
    evaluation = meta["evaluation"]
    assert evaluation["trials"] == 2 and set(evaluation["rate"]) == {"policy", "distributed"}
    mine, theirs = (np.array(evaluation["per_trial"][k]) for k in ("policy", "distributed"))
    assert evaluation["difference"]["mean"] == pytest.approx((mine - theirs).mean())
    page, figure = tmp_path / "page.md", tmp_path / "curves.png"
    assert learned.main(["report", str(out), "--out", str(page), "--figure", str(figure)]) == 0
    assert "| bc (small) | steps=30 | 300 |" in page.read_text()  # 2 trials, 30 steps, 5 UAVs
    assert matplotlib.image.imread(figure).shape[2] in (3, 4)
    capsys.readouterr()
    for bad in (["bc", "--out", str(tmp_path / "no" / "x.npz")],
                ["bc", "--out", str(tmp_path / "x.npz"), "--set", "sensor.detection_probability=2"],
                ["bc", "--out", str(tmp_path / "x.npz"), "--epochs", "0"],
                ["mappo", "--out", str(tmp_path / "x.npz"), "--frames", "10"],
                ["report", str(tmp_path / "missing.npz")]):  # fmt: skip
        assert learned.main(bad) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "x.npz").exists() and not list(tmp_path.glob("*.part*"))


def test_a_policy_file_changed_between_two_runs_is_read_anew(tmp_path):
    """In one process and in a results folder alike: the file, not its name, is what
    flies, and a sweep's stored results of the old file are not taken for the new."""
    path = tmp_path / "p.npz"
    constant(1).save(path)
    straight = uavtrack.run(SHORT, f"policy:{path}", seeds=[0], trace=True)
    pursuit().save(path)
    chased = uavtrack.run(SHORT, f"policy:{path}", seeds=[0], trace=True)
    assert straight.traces is not None and chased.traces is not None
    assert (np.asarray(straight.traces[0].action) == 0).all()
    assert (np.asarray(chased.traces[0].action) != 0).any()
    argv = ["sweep", "comm_range", "30", "100", "--method", f"policy:{path}", "--trials", "1",
            "--steps", "20", "--workers", "1", "--out", str(tmp_path / "sweep")]  # fmt: skip
    assert cli.main(argv) == 0
    constant(0).save(path)
    assert cli.main(argv) == 0
    rejected = list((tmp_path / "sweep" / "failed").glob("*.rejected*"))
    assert len(rejected) == 2  # both old results set aside, both jobs run again
    assert "another policy" in rejected[0].read_text()


def test_a_policy_that_does_not_fit_a_cell_stops_a_sweep_before_any_work(tmp_path, capsys):
    code = cli.main(["sweep", "n_uavs", "2", "5", "--method", "policy:bc", "--trials", "1",
                     "--steps", "10", "--workers", "1", "--out", str(tmp_path / "s")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "does not fit" in err and "Traceback" not in err
    assert not list((tmp_path / "s").glob("raw/*.json"))


def test_bad_policy_files_are_named_in_one_line(tmp_path):
    (tmp_path / "folder.npz").mkdir()
    (tmp_path / "text.npz").write_text("not an archive")
    np.savez(tmp_path / "list.npz", meta=np.array(json.dumps([1, 2])), W0=np.zeros((2, 3)),
             b0=np.zeros(3))  # fmt: skip
    for name, named in (("folder.npz", "is a folder"), ("text.npz", "not a NumPy archive"),
                        ("list.npz", "not a JSON object")):  # fmt: skip
        with pytest.raises(UsageError, match=named) as caught:
            Policy.load(tmp_path / name)
        assert "allow_pickle" not in str(caught.value)
    with pytest.raises(ValueError, match="real floats"):
        Policy(layers=[(np.zeros((SIZE, 3), dtype=complex), np.zeros(3))])


def test_the_trainer_refuses_bad_input_and_an_interruption_leaves_no_file(
    tmp_path, capsys, monkeypatch
):
    out = tmp_path / "x.npz"
    small = ["--rounds", "1", "--trials-per-round", "2", "--hidden", "8", "--epochs", "1",
             "--trials", "2", "--set", "steps=20"]  # fmt: skip
    (tmp_path / "exists.npz").write_bytes(b"mine")
    for argv in (["bc", "--out", str(tmp_path)],
                 ["bc", "--out", str(tmp_path / "exists.npz"), *small],
                 ["bc", "--out", str(out), "--learning-rate", "nan"],
                 ["bc", "--out", str(out), "--set", "n_uavs=2"],
                 ["evaluate", "bc"],
                 ["evaluate", str(out), "--set", "steps=10"],
                 ["report", "policy.npz", "--out", str(tmp_path / "no" / "page.md")]):  # fmt: skip
        assert learned.main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, (argv, err)
    assert (tmp_path / "exists.npz").read_bytes() == b"mine"

    def interrupted(*_, **__):
        raise KeyboardInterrupt

    for stage in ("imitate", "evaluate"):  # while training, and while evaluating
        with monkeypatch.context() as m:
            m.setattr(learned, stage, interrupted)
            assert learned.main(["bc", "--out", str(out), *small]) == 130
        assert "interrupted" in capsys.readouterr().err
        assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["exists.npz"]


def test_evaluate_flies_the_scenario_the_file_was_trained_on(tmp_path):
    out = tmp_path / "x.npz"
    assert learned.main(["bc", "--rounds", "1", "--trials-per-round", "2", "--hidden", "8",
                         "--epochs", "1", "--trials", "2", "--set", "steps=25",
                         "--out", str(out)]) == 0  # fmt: skip
    assert learned.main(["evaluate", str(out), "--trials", "3"]) == 0
    evaluation = Policy.load(out).meta["evaluation"]
    assert evaluation["scenario"] == {"steps": 25} and evaluation["trials"] == 3
    rates = np.array(evaluation["per_trial"]["policy"]) * 25
    np.testing.assert_allclose(rates * 4, np.round(rates * 4))  # 4 targets, 25 steps


def test_fine_tuning_starts_from_the_imitation_weight_for_weight():
    """PPO's actor is the start's perceptron, copied weight for weight: its greedy action
    is the policy's on observations of a trial; with a learning rate of 0 the exported
    policy is the start; with one above 0 the actor moves once the critic has warmed."""
    pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    start = pursuit_mlp()
    frozen = learned.FineTuning(frames=2560, warm=1280, trials=2, learning_rate=0.0)
    model, _ = learned.ppo_from(SHORT, start, frozen)
    observations = model.get_env().reset()
    greedy, _ = model.predict(observations, deterministic=True)
    np.testing.assert_array_equal(greedy, start.act(observations))
    assert len(np.unique(greedy)) > 1  # a test of more than one action
    same = learned.fine_tune(SHORT, start, frozen, seed=0, log=lambda _: None)
    for (W, b), (W0, b0) in zip(same.layers, start.layers, strict=True):
        np.testing.assert_array_equal(W, W0)
        np.testing.assert_array_equal(b, b0)
    assert same.meta["row"] == "bc-ppo" and same.meta["frames"] >= 2560
    moving = learned.FineTuning(frames=2560, warm=1280, trials=2, learning_rate=1e-3)
    moved = learned.fine_tune(SHORT, start, moving, seed=0, log=lambda _: None)
    pairs = zip(moved.layers, start.layers, strict=True)
    assert any(not np.array_equal(W, W0) for (W, _), (W0, _) in pairs)


def pursuit_mlp(hidden=16):
    """`pursuit` as a tanh perceptron with one hidden layer (the shape PPO's actor takes):
    the hidden units carry the sine of the nearest target's bearing."""
    W0 = np.zeros((SIZE, hidden), dtype=np.float32)
    W0[len(OWN) + TARGET.index("sin_bearing"), :] = 1.0
    W1 = np.zeros((hidden, 3), dtype=np.float32)
    W1[:, 0], W1[:, 2] = -10.0 / hidden, 10.0 / hidden
    b1 = np.array([0.0, 0.3, 0.0], dtype=np.float32)
    return Policy(layers=[(W0, np.zeros(hidden, dtype=np.float32)), (W1, b1)])


def test_a_policys_report_names_no_target_and_no_bids_and_a_planners_must():
    """The world admits from a policy's UAV exactly what the batch records of it: no
    target (-1) and no bid (NaN); from a planner's, a target and scored bids."""
    pytest.importorskip("msgspec")
    from uavtrack.agents.messages import VERSION, Report, Spec, packed

    scenario = uavtrack.Scenario()
    m = scenario.n_targets
    mean = np.tile([100.0, 100.0, 0.0, 0.0], (m, 1))
    cov = np.broadcast_to(np.eye(4), (m, 4, 4)).copy()

    def report(target: int, bids: np.ndarray) -> Report:
        return Report(
            version=VERSION, run="r", k=0, uav=0, action=1, target=target,
            mean=packed({"x": mean})["x"], cov=packed({"x": cov})["x"],
            bids=packed({"x": bids})["x"], rounds=1, sent=0, delivered=0,
            decision_ms=0.1, decision_wall_ms=0.1, late={}, radio_bytes=0,
        )  # fmt: skip

    policy, planner = Spec.of(scenario, False, plans=False), Spec.of(scenario, False)
    none, scored = np.full(m, np.nan), np.ones(m)
    assert isinstance(policy.report(report(-1, none)), dict)
    assert policy.report(report(0, none)) == "action or target out of range"
    assert policy.report(report(2**62, none)) == "action or target out of range"
    assert policy.report(report(-1, scored)) == "bids of a method that does not bid"
    assert isinstance(planner.report(report(0, scored)), dict)
    assert planner.report(report(-1, none)) == "action or target out of range"
    assert planner.report(report(0, none)) == "bids not scored"
    # the beacon carries the whole state for the policy, the position for the planner
    assert list(policy.contents("beacon") or {}) == ["uav"]
    assert list(planner.contents("beacon") or {}) == ["position"]


def graph_policy(seed=0, hidden=8, size=SIZE):
    rng = np.random.default_rng(seed)
    draw = lambda *shape: rng.normal(0, 0.5, shape).astype(np.float32)  # noqa: E731
    return Policy(
        graph=(draw(size, hidden), draw(size, hidden), draw(hidden)),
        layers=[(draw(hidden, hidden), draw(hidden)), (draw(hidden, 3), draw(3))],
        meta={"row": "test"},
    )


def team_observations():
    """One cycle's observations (1, 5, size) of the paper's team, some UAVs in range."""
    episodes = Episodes(
        SHORT, get("distributed"), Spaces(SHORT), "team", [np.random.SeedSequence(1)], plan=False
    )
    return Spaces(SHORT, "box", 4, 4), episodes.view()


def test_a_graph_policy_sums_its_neighbours_within_the_radio_range(tmp_path):
    """The graph layer: a UAV alone reads only itself; a neighbour within r_C adds its
    observation through G_rel; the layer is equivariant to the UAVs' order; the file
    keeps it."""
    spaces, view = team_observations()
    x = spaces.observe(view)
    assert isinstance(x, np.ndarray)
    policy = graph_policy()
    root, rel, bias = policy.graph  # type: ignore[misc]
    where = spaces.positions(x)[0]
    apart = np.linalg.norm(where[:, None] - where[None], axis=-1) * spaces.half
    believed = view.believed[0]
    true = np.linalg.norm(believed[:, None, :3] - believed[None, :, :3], axis=-1)
    np.testing.assert_allclose(apart, true, atol=1e-3)  # positions: metres / half-field
    linked = (true <= SHORT.comm_range) & ~np.eye(SHORT.n_uavs, dtype=bool)
    assert linked.any() and not linked.all()
    first = x[0] @ root + (linked.astype(np.float32) @ x[0]) @ rel + bias
    h = np.tanh(first @ policy.layers[0][0] + policy.layers[0][1])  # no activation between
    expected = h @ policy.layers[1][0] + policy.layers[1][1]
    np.testing.assert_allclose(policy.logits(x, spaces)[0], expected, rtol=1e-4, atol=1e-5)
    order = np.array([3, 0, 4, 1, 2])
    np.testing.assert_allclose(
        policy.logits(x[:, order], spaces)[0], expected[order], rtol=1e-4, atol=1e-5
    )
    loaded = Policy.load(policy.save(tmp_path / "g.npz"))
    assert loaded.graph is not None
    np.testing.assert_array_equal(loaded.logits(x, spaces), policy.logits(x, spaces))
    with pytest.raises(ValueError, match="team's observations"):
        policy.logits(x[0, 0])


def test_a_graph_policy_flies_in_the_batch_and_is_refused_by_the_agent_form(tmp_path, capsys):
    path = graph_policy().save(tmp_path / "g.npz")
    code = learned.main(["bc-ppo", "--start", str(path), "--out", str(tmp_path / "t.npz")])
    assert code == 2 and "graph policy" in capsys.readouterr().err
    method = get(f"policy:{path}")
    assert not method.local and get("distributed").local
    result = uavtrack.run(SHORT, f"policy:{path}", seeds=[2])
    assert 0.0 <= result.metrics["observation_rate"][0] <= 1.0
    code = cli.main(["swarm", "--method", f"policy:{path}", "--steps", "3"])
    err = capsys.readouterr().err
    assert code == 2 and "whole team's observations" in err and "Traceback" not in err


def test_the_report_draws_a_marl_rows_curve_and_tables_its_rate(tmp_path):
    """A BenchMARL row's file (here a graph policy with the meta such a row records):
    evaluated on its scenario, tabled, and its curve drawn on the figure."""
    import matplotlib.image

    path = tmp_path / "gnn.npz"
    meta = {"row": "mappo-gnn", "frames": 1000, "cpu_seconds": 36.0, "command": "c",
            "curve": [[100, 0.1], [200, 0.3]], "scenario": {"steps": 30}}  # fmt: skip
    replace(graph_policy(), meta=meta).save(path)
    result = learned.record(path, trials=2)
    assert result["scenario"] == {"steps": 30}
    figure = tmp_path / "curves.png"
    page = learned.report([path], figure, tmp_path / "page.md")
    assert "| mappo-gnn (gnn) | steps=30 | 1,000 | 0.01 | 2 |" in page
    assert matplotlib.image.imread(figure).shape[2] in (3, 4)
