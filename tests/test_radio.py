import numpy as np

from uavtrack import faults, fusion, network
from uavtrack.config import FaultModel
from uavtrack.radio import Radio, RadioState, counted


def path_links(n=3):
    adj = np.zeros((1, n, n), dtype=bool)
    for k in range(n - 1):
        adj[0, k, k + 1] = adj[0, k + 1, k] = True
    return network.links(adj)


def realisation(**fields):
    return faults.Faults(FaultModel(**fields), np.array([[7, 11]], dtype=np.uint32), 3)


def test_without_faults_a_round_arrives_in_the_same_round():
    f, alive = realisation(), np.ones((1, 3), dtype=bool)
    radio = Radio(0, path_links(), alive, f, RadioState())
    radio.send("consensus", {"x": np.array([[1.0, 2.0, 3.0]])})
    inbox = radio.receive("consensus", 1)
    assert np.array_equal(inbox.content["x"], [[1.0, 2.0, 3.0]])
    assert np.array_equal(inbox.delivered.dense, inbox.links.dense)
    assert radio.close() == RadioState((), None)


def test_a_delayed_message_arrives_in_the_same_round_delay_cycles_later():
    f, alive = realisation(delay=2), np.ones((1, 3), dtype=bool)
    state, received = RadioState(), []
    for k in range(5):
        links = path_links() if k != 1 else network.links(np.zeros((1, 3, 3), dtype=bool))
        radio = Radio(k, links, alive, f, state)
        radio.send("consensus", {"x": np.full((1, 3), 10.0 * k + 1)})  # round 1
        radio.send("consensus", {"x": np.full((1, 3), 10.0 * k + 2)})  # round 2
        first, third = radio.receive("consensus", 1), radio.receive("consensus", 3)
        received.append(None if first is None else (first, third))
        state = radio.close()
    assert received[0] is None and received[1] is None  # nothing in flight yet
    first, third = received[2]
    assert first.content["x"][0, 0] == 1.0  # round 1 of cycle 0
    assert third.content["x"][0, 0] == 2.0  # cycle 0 ran 2 rounds: its last state
    assert first.links.dense[0, 0, 1]  # over cycle 0's links
    first, _ = received[3]
    assert first.content["x"][0, 0] == 11.0 and not first.links.dense[0, 0, 1]  # cycle 1: no link
    assert len(state.history) == 2


def test_lost_messages_are_not_delivered_but_self_links_stay():
    f, alive = realisation(loss=1.0), np.ones((1, 3), dtype=bool)
    radio = Radio(0, path_links(), alive, f, RadioState())
    radio.send("bids", {"bids": np.zeros((1, 3, 2))})
    inbox = radio.receive("bids")
    assert inbox.links.incoming().sum() == 4 and inbox.delivered.incoming().sum() == 0
    assert np.array_equal(inbox.delivered.dense[0], np.eye(3, dtype=bool))
    radio.send("upload", {"x": np.zeros((1, 3))})
    content, delivered = radio.receive_central("upload")
    assert not delivered.any()


def never():
    raise AssertionError("this side of the count does not apply")


def test_messages_count_where_they_arrive_without_delay_and_when_sent_with_it():
    # the rule alone: one side applies, its pairs summed
    arrived = [(np.array([3, 1]), np.array([2, 1])), (np.array([4, 0]), np.array([4, 0]))]
    sent, delivered = counted(0, never, arrived)
    assert sent.tolist() == [7, 1] and delivered.tolist() == [6, 1]
    assert counted(2, lambda: [(5, 4), (1, 1)], (never() for _ in range(1))) == (6, 5)
    assert counted(0, never, []) == (0, 0)

    # on the path 0 - 1 - 2, UAV 1 alone still receiving, every message lost: without
    # delay the two messages into UAV 1 were sent and none delivered
    receiving = np.array([[False, True, False]])
    alive = np.ones((1, 3), dtype=bool)
    for loss, expected in ((0.0, (2, 2)), (1.0, (2, 0))):
        radio = Radio(0, path_links(), alive, realisation(loss=loss), RadioState())
        radio.send("flood", {"known": np.zeros((1, 3, 3), dtype=bool)})
        inbox = radio.receive("flood", 1)
        zero = np.zeros(1, dtype=np.int64)
        pairs = [fusion.count(inbox, receiving, zero, zero)]
        assert tuple(int(x[0]) for x in counted(0, never, pairs)) == expected

    # with delay 1 nothing arrives in cycle 0, yet what is sent now counts: UAV 0 runs
    # one round over one link, UAV 1 two rounds over two links, UAV 2 none
    rounds = np.array([[1, 2, 0]])
    for loss, expected in ((0.0, (5, 5)), (1.0, (5, 0))):
        radio = Radio(0, path_links(), alive, realisation(delay=1, loss=loss), RadioState())
        radio.send("flood", {"known": np.zeros((1, 3, 3), dtype=bool)})
        assert radio.receive("flood", 1) is None
        sent, delivered = counted(1, lambda r=radio: [r.transmitted("flood", rounds)], [])
        assert (int(sent[0]), int(delivered[0])) == expected
