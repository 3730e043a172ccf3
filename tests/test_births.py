"""Targets that come and go (``target.stay``): the presence process, the truth it leaves
alone, the observation rate over the targets present, and the outputs that read it."""

import numpy as np
import pytest

import uavtrack
from uavtrack import ScenarioError, simulation, world
from uavtrack.tracks import manage

BIRTHS = {
    "tracker.association": "jpda",
    "target.stay": 20,
    "target.away": 10,
    "steps": 120,
}


def test_stays_and_absences_are_geometric_with_their_means(rng):
    """Over many targets and steps: the share of steps present is stay / (stay + away),
    and a stay lasts `stay` steps on average (each within 5 standard errors)."""
    stay, away, n, T = 20.0, 10.0, 2000, 2000
    here = world.presence(np.ones((1, n), bool), rng.random((1, T, n)), stay, away)[0]
    share = here[T // 2 :].mean()
    assert share == pytest.approx(stay / (stay + away), abs=0.01)
    starts = (here[1:] & ~here[:-1]).sum()  # stays begun after step 0
    ends = (~here[1:] & here[:-1]).sum()
    mean_stay = here[1:].sum() / max(ends, 1)
    assert abs(mean_stay - stay) < 5 * stay / np.sqrt(ends)
    assert abs(starts - ends) <= n  # each place alternates


def test_targets_that_come_and_go_move_as_the_fixed_set_does(monkeypatch):
    """Every target is there at step 0; where a target is present its state is the fixed
    set's bit for bit, whatever the block size; away it is NaN."""
    fixed = uavtrack.Scenario(steps=200).with_overrides({"tracker.association": "jpda"})
    coming = fixed.with_overrides({"target.stay": 15, "target.away": 5})
    seeds = [np.random.SeedSequence(5), np.random.SeedSequence(6)]

    def states(scenario, block):
        monkeypatch.setattr(world.Targets, "BLOCK", block)
        return simulation.initial_stream(scenario, seeds, keep=True)[1].whole()

    truth = states(fixed, 1024)
    seen = states(coming, 7)
    here = ~np.isnan(seen[..., 0])
    assert here[:, 0].all() and not here.all()
    assert np.array_equal(seen[here], truth[here])
    assert np.isnan(seen[~here]).all()
    assert np.array_equal(states(coming, 1024), seen, equal_nan=True)


def test_a_stay_nobody_ends_changes_nothing():
    """target.stay 1e6 over 60 steps: no target leaves, and the run is the fixed set's
    exactly (the presence stream is apart from the others)."""
    fixed = uavtrack.Scenario(steps=60).with_overrides({"tracker.association": "jpda"})
    long = fixed.with_overrides({"target.stay": 1e6})
    a = uavtrack.simulate(fixed, "distributed", seed=2)
    b = uavtrack.simulate(long, "distributed", seed=2)
    assert not np.isnan(b.trace.targets).any()
    assert np.array_equal(a.trace.action, b.trace.action)
    assert a.observation_rate == b.observation_rate


@pytest.mark.parametrize("method", ["distributed", "centralized"])
def test_the_observation_rate_counts_the_targets_present(method):
    """No UAV observes a target that is away, and the rate is the present target-steps
    some UAV holds in view over all present target-steps."""
    scenario = uavtrack.Scenario().with_overrides(BIRTHS)
    result = uavtrack.simulate(scenario, method, seed=4)
    trace = result.trace
    here = ~np.isnan(trace.targets[..., 0])  # (T, Nt)
    assert not here.all()
    assert not trace.observed[~here[:, None, :].repeat(scenario.n_uavs, axis=1)].any()
    in_view = trace.observed.any(axis=1)
    assert result.observation_rate == pytest.approx(in_view[here].sum() / here.sum())


@pytest.mark.parametrize(
    "overrides,message",
    [
        ({"target.stay": 0.5}, "target.stay 0.5 must be 0"),
        ({"target.away": 50}, "target.away needs target.stay > 0"),
        ({"target.stay": 100}, "needs tracker.association = gnn or jpda"),
        ({"planner.existence": True}, "planner.existence needs tracks"),
        (
            {
                "planner.existence": True,
                "tracker.association": "gnn",
                "tracker.confirmation": "m_of_n",
            },
            "planner.existence needs tracks",
        ),  # fmt: skip
    ],
)
def test_settings_that_cannot_work_are_refused(overrides, message):
    with pytest.raises(ScenarioError, match=message):
        uavtrack.Scenario().with_overrides(overrides)


def test_bids_weighed_by_existence_only_when_asked():
    bids = np.array([[[2.0, 4.0]]])
    book = manage.briefed(np.zeros((1, 1, 2, 4)), np.tile(np.eye(4), (1, 1, 2, 1, 1)), 2)[0]
    book = manage.Book(**{**book.__dict__, "existence": np.array([[[0.5, 0.25]]])})
    tracked = uavtrack.Scenario().with_overrides({"tracker.association": "jpda"})
    assert manage.weighed(bids, book, tracked) is bids
    weighed = manage.weighed(bids, book, tracked.with_overrides({"planner.existence": True}))
    assert weighed.tolist() == [[[1.0, 1.0]]]


def test_stone_soup_reads_each_stay_as_its_own_truth():
    """to_stonesoup gives a GroundTruthPath per stay of a target, with finite states at
    exactly the steps it was present."""
    pytest.importorskip("stonesoup")
    from uavtrack.io.stonesoup import to_stonesoup

    scenario = uavtrack.Scenario().with_overrides(BIRTHS)
    trace = uavtrack.simulate(scenario, "distributed", seed=4).trace
    truths, _ = to_stonesoup(trace, scenario.dt)
    here = ~np.isnan(trace.targets[..., 0])
    stays = sum(int(here[0, j]) + int((here[1:, j] & ~here[:-1, j]).sum()) for j in range(4))
    assert len(truths) == stays
    assert sum(len(path) for path in truths) == here.sum()
    for path in truths:
        assert all(np.isfinite(state.state_vector).all() for state in path)


def test_tables_mark_the_targets_present():
    pd = pytest.importorskip("pandas")
    from uavtrack.io.tables import to_frames

    scenario = uavtrack.Scenario().with_overrides(BIRTHS)
    trace = uavtrack.simulate(scenario, "distributed", seed=4).trace
    targets = to_frames(trace, scenario.dt)["targets"]
    assert isinstance(targets, pd.DataFrame)
    assert (targets["present"] == targets["x"].notna()).all()
    assert (~targets["present"]).any()
    assert not targets.loc[~targets["present"], "in_view"].any()


def test_a_bag_shows_only_the_targets_present(tmp_path):
    """rosbags reads a truth marker per present target and step, at its place."""
    pytest.importorskip("rosbags")
    from rosbags.highlevel import AnyReader

    from uavtrack.io.bag import write_bag

    scenario = uavtrack.Scenario().with_overrides({**BIRTHS, "steps": 40, "target.stay": 8})
    trace = uavtrack.simulate(scenario, "distributed", seed=4).trace
    write_bag(tmp_path / "run", trace, scenario, origin=(47.0, 8.0))
    here = ~np.isnan(trace.targets[..., 0])
    assert not here.all()
    with AnyReader([tmp_path / "run"]) as reader:
        chosen = [c for c in reader.connections if c.topic == "/targets/truth"]
        for k, (c, _, raw) in enumerate(reader.messages(chosen)):
            markers = reader.deserialize(raw, c.msgtype).markers
            assert markers[0].action == 3  # DELETEALL: a target that left leaves the view
            markers = markers[1:]
            assert [m.id for m in markers] == np.flatnonzero(here[k]).tolist()
            for m in markers:
                assert m.pose.position.x == trace.targets[k, m.id, 0]


def test_stone_soup_detections_point_at_the_stay_they_measured():
    """Each true detection's ground-truth path has a state at the detection's time."""
    pytest.importorskip("stonesoup")
    from uavtrack.io.stonesoup import to_detections

    scenario = uavtrack.Scenario().with_overrides(
        {**BIRTHS, "sensor.detection_probability": 0.9, "sensor.clutter_rate": 1.0}
    )
    trace = uavtrack.simulate(scenario, "distributed", seed=4).trace
    here = ~np.isnan(trace.targets[..., 0])
    assert (here[1:] & ~here[:-1]).any()  # some target entered after step 0
    true = 0
    for time, detections in to_detections(trace, scenario.dt):
        for d in detections:
            path = getattr(d, "groundtruth_path", None)
            if path is not None:
                true += 1
                assert time in {state.timestamp for state in path}, path.id
    assert true > 0


def test_the_environment_counts_the_targets_present():
    """The environment's observation rate and its team reward read the targets present,
    as the run's metrics do."""
    from uavtrack.env import parallel_env

    settings = {**BIRTHS, "steps": 60, "target.stay": 10, "target.away": 5}
    scenario = uavtrack.Scenario().with_overrides(settings)
    env = parallel_env(scenario=scenario, reward="team")
    env.reset(seed=3)
    earned = []
    while env.agents:
        _, reward, *_ = env.step({a: 0 for a in env.agents})
        earned.append(np.mean(list(reward.values())))
    result = env.result()
    here = ~np.isnan(result.trace.targets[..., 0])
    assert not here.all()
    in_view = result.trace.observed.any(axis=1)
    share = (in_view & here).sum(axis=1) / np.maximum(here.sum(axis=1), 1)  # none: 0
    assert env.unwrapped._run.observation_rate()[0] == pytest.approx(result.observation_rate)
    assert np.allclose(earned[:-1], share[1:], atol=1e-12)  # a step earns the next's share
