import numpy as np
import pytest

import uavtrack
from uavtrack import faults
from uavtrack.config import FaultModel

KAT = [  # Random123 kat_vectors: counter (4 words), key (2 words), expected output
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    (
        (0xFFFFFFFF,) * 4,
        (0xFFFFFFFF,) * 2,
        (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD),
    ),
    (
        (0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344),
        (0xA4093822, 0x299F31D0),
        (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1),
    ),
]


@pytest.mark.parametrize("counter,key,expected", KAT)
def test_philox_known_answers(counter, key, expected):
    out = faults.philox(counter, key)
    assert tuple(int(w) for w in out) == expected


def test_philox_broadcasts_elementwise():
    counters = np.array([k[0] for k in KAT], dtype=np.uint64).astype(np.uint32).T
    keys = np.array([k[1] for k in KAT], dtype=np.uint64).astype(np.uint32).T
    out = np.stack(faults.philox(tuple(counters), tuple(keys)))
    assert [tuple(int(w) for w in out[:, j]) for j in range(3)] == [k[2] for k in KAT]


def realisation(batch=2, n=6, **fields):
    keys = np.stack([faults.trial_key(np.random.SeedSequence(100 + b)) for b in range(batch)])
    return faults.Faults(FaultModel(**fields), keys, n)


def test_uniforms_are_uniform_and_a_pure_function_of_the_counter():
    key = faults.trial_key(np.random.SeedSequence(1))
    step = np.arange(200_000)
    u = faults.uniform(key, step, faults.what("bids"), 3, 4)
    assert 0 <= u.min() and u.max() < 1
    assert abs(u.mean() - 0.5) < 4 * np.sqrt(1 / 12 / u.size)
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01
    again = faults.uniform(key, step[[5, 7]], faults.what("bids"), 3, 4)
    assert np.array_equal(again, u[[5, 7]])
    other = faults.uniform(key, step[:5], faults.what("bids"), 4, 3)  # reversed link
    assert not np.array_equal(other, u[:5])


def test_independent_loss_rate_and_no_dependence_on_the_batch():
    f = realisation(batch=3, loss=0.3)
    trial, sender, receiver = np.ogrid[:3, :40, :40]
    lost = np.stack([f.lost(k, "consensus", 2, trial, sender, receiver) for k in range(60)])
    assert abs(lost.mean() - 0.3) < 4 * np.sqrt(0.3 * 0.7 / lost.size)
    # the trial's key alone decides: the same trial in another batch loses the same messages
    alone = faults.Faults(f.model, f.key[1:2], f.n)
    zero = np.zeros_like(trial[1:2])
    assert np.array_equal(alone.lost(7, "consensus", 2, zero, sender, receiver), lost[7, 1:2])
    assert not f.lost(7, "bids", 0, trial, sender, receiver).shape == ()
    assert faults.Faults(FaultModel(loss=1.0), f.key, f.n).lost(0, "bids", 0, trial, 0, 1).all()


def test_gilbert_elliott_long_run_loss_and_burst_length():
    f = realisation(batch=4, n=9, loss=0.2, burst_length=6.0)
    bad, history = None, []
    for k in range(1500):
        bad = f.link_states(k, bad)
        history.append(bad)
    states = np.stack(history)  # (T, B, N+1, N+1)
    assert abs(states.mean() - 0.2) < 0.02
    runs = []
    for link in states.reshape(len(history), -1).T:
        edges = np.diff(np.r_[0, link.astype(int), 0])
        runs.extend(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1))
    assert abs(np.mean(runs) - 6.0) < 0.4
    # a bad link loses every message of the cycle, whatever the protocol or round
    trial, receiver, sender = np.nonzero(bad)
    assert f.lost(1499, "flood", 3, trial, sender, receiver, bad).all()


def test_position_errors_have_the_given_spread():
    f = realisation(batch=5, n=8, position_std=4.0)
    errors = np.stack([f.position_error(k) for k in range(500)])  # (T, B, N, 2)
    assert errors.shape == (500, 5, 8, 2)
    assert abs(errors.mean()) < 0.1 and abs(errors.std() - 4.0) < 0.1
    assert abs(np.corrcoef(errors[..., 0].ravel(), errors[..., 1].ravel())[0, 1]) < 0.02
    assert realisation(position_std=0.0).position_error(3) is None


def test_failures_listed_and_random():
    f = realisation(batch=2, n=4, failures=((1, 5),))
    alive = np.ones((2, 4), dtype=bool)
    for k in range(10):
        alive = f.alive(k, alive)
        assert alive[:, 1].all() == (k < 5) and alive[:, [0, 2, 3]].all()
    f = realisation(batch=50, n=40, failure_rate=0.01)
    alive = np.ones((50, 40), dtype=bool)
    for k in range(20):
        alive = f.alive(k, alive)
    expected = 1 - 0.99**20
    assert abs((~alive).mean() - expected) < 4 * np.sqrt(expected * (1 - expected) / alive.size)


def test_faults_are_active_only_when_set():
    assert not realisation().active
    for fields in ({"loss": 0.1}, {"delay": 1}, {"round_budget": 3}, {"position_std": 1.0}):
        assert realisation(**fields).active, fields


@pytest.mark.parametrize(
    "overrides,message",
    [
        ({"faults.loss": -0.1}, "faults.loss: Input should be greater than or equal to 0"),
        ({"faults.loss": 1.5}, "faults.loss: Input should be less than or equal to 1"),
        ({"faults.failures": [[9, 3]]}, "faults.failures names UAV 9, which does not exist"),
        ({"faults.delay": -1}, "faults.delay: Input should be greater than or equal to 0"),
        ({"faults.burst_length": 0.5}, "faults.burst_length: Input should be greater than"),
        (
            {"faults.loss": 0.5, "faults.burst_length": 1.5},
            "burst_length 1.5 is shorter than 2",
        ),
        ({"faults.position_std": -1}, "faults.position_std: Input should be greater"),
        ({"robust.stale": "yes"}, "robust.stale: Input should be a valid boolean"),
        ({"faults.failures": [[0, 500]]}, "names step 500, after the run's last step 499"),
        ({"faults.failures": [[0, 10], [0, 5]]}, "lists UAV 0 twice"),
        ({"faults.loss": 1.0, "faults.burst_length": 5}, "needs 0 < loss < 1"),
        ({"faults.burst_length": 5}, "needs 0 < loss < 1"),
    ],
)
def test_bad_fault_values_name_the_field(overrides, message):
    with pytest.raises(uavtrack.ScenarioError, match=message):
        uavtrack.Scenario().with_overrides(overrides)


def test_listed_failures_have_one_order():
    a = uavtrack.Scenario().with_overrides({"faults.failures": [[3, 10], [1, 5]]})
    b = uavtrack.Scenario().with_overrides({"faults.failures": [[1, 5], [3, 10]]})
    assert a == b and a.faults.failures == ((1, 5), (3, 10))


def test_with_every_uav_failed_nothing_is_averaged():
    r = uavtrack.simulate(uavtrack.Scenario(steps=10, faults={"failure_rate": 1.0}), trace=False)
    assert r.failed == 5 and r.observation_rate == 0.0
    for name in (
        "rmse",
        "rmse_best",
        "nees",
        "nees_best",
        "nees_median",
        "nees_inside",
        "nees_best_median",
        "nees_best_inside",
        "rounds",
        "decision_time_ms",
        "decision_wall_ms",
    ):
        assert np.isnan(getattr(r, name)), name


@pytest.mark.parametrize("method", ["distributed", "greedy", "centralized"])
def test_with_delay_messages_are_counted_when_sent(method):
    # a delay longer than the run: nothing is ever read, yet every UAV sends every cycle
    scenario = uavtrack.Scenario(steps=12).with_overrides({"faults.delay": 50})
    trace = uavtrack.simulate(scenario, method, seed=1).trace
    assert (trace.messages > 0).all() and (trace.delivered == trace.messages).all()
    # what is sent: per link of the cycle, the rounds each UAV runs (no flooding knowledge
    # ever arrives, so one flooding round, no consensus round, a beacon and bids)
    adjacency = np.stack(
        [uavtrack.network.adjacency(trace.uavs[k], scenario.comm_range) for k in range(12)]
    )
    links = adjacency.sum(axis=(1, 2))
    expected = {"distributed": 3 * links, "greedy": links, "centralized": 2 * 5 + 0 * links}
    np.testing.assert_array_equal(trace.messages, expected[method])
    # losses count among what was sent
    lossy = scenario.with_overrides({"faults.loss": 0.5})
    lossy_trace = uavtrack.simulate(lossy, method, seed=1).trace
    assert (lossy_trace.delivered <= lossy_trace.messages).all()
    assert lossy_trace.delivered.sum() < lossy_trace.messages.sum()
