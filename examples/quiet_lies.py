"""Lies that pass every check of a single message, and what the receivers' own checks
do against them (docs: Security, "A lying member").

UAV `LIAR` runs the honest program but changes what it sends:

* ``tombstones``: in every consensus round (tracks of unknown association), its
  tombstones name every label it holds, deleted at the current cycle, as if it had
  looked at every target and seen none. Its tracks go with them, which no honest
  sender does (it buries what it deletes): the receivers refuse the message.
* ``tombstones-hidden``: the same tombstones, its slots sent empty, so that nothing in
  the message contradicts them.
* ``beacons``: with the avoidance filter at one altitude (``--config one-altitude``),
  each receiver gets a beacon placed 5 m ahead of where that receiver was last heard,
  flown on one step, with its heading and speed: a phantom the receiver must give way
  to. The receivers check each beacon against the sender's earlier one, the radio's
  range and the known start (`uavtrack.airspace.beacons`).

Each lying swarm runs over the in-process transport (the agent form itself); the honest
runs are the simulator's (the agent form equals it, seed for seed).

    python examples/quiet_lies.py                      # every lie, 20 trials of 500 steps
    python examples/quiet_lies.py --lie beacons --trials 4 --steps 100

prints, as JSON, per lie the mean observation rate of the honest and the lying team,
their paired difference (95% t interval) and what the receivers refused, by reason.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

import uavtrack
from uavtrack.agents import agent, run_swarm
from uavtrack.agents.messages import Array, Part
from uavtrack.experiments.jobs import paired

LIAR = 1
"""The lying member."""
AHEAD = 5.0
"""How far ahead of each receiver the phantom of ``beacons`` flies [m]."""
DEADLINE = 0.1
"""Each wait's deadline [s]: a refused message costs its receivers one."""
TRACKED = {
    "tracker.association": "jpda",
    "sensor.detection_probability": 0.9,
    "sensor.clutter_rate": 2.0,
}
"""The sensing of the tombstone lies: missed detections, clutter, unknown association."""


def scenario_of(what: str, steps: int) -> uavtrack.Scenario:
    """The scenario each lie runs in."""
    if what == "beacons":
        return uavtrack.Scenario.from_toml("one-altitude").with_overrides({"steps": steps})
    return uavtrack.Scenario(steps=steps).with_overrides(TRACKED)


def tombstoned(content: dict[str, Array], k: int, hide: bool) -> dict[str, Array]:
    """A consensus content whose tombstones name every label the sender holds, at k."""
    label, status = content["label"].array(), content["status"].array()
    held = label[status != 0]
    tombs = np.full((label.size, 2), -1, dtype=np.int64)
    tombs[: held.size, 0], tombs[: held.size, 1] = held, k
    out = dict(content, tombs=Array.of(tombs))
    if hide:
        out["status"] = Array.of(np.zeros(label.size, dtype=np.int64))
        out["label"] = Array.of(np.full(label.size, -1, dtype=np.int64))
    return out


def phantom(heard, me: int, q: int, k: int, dt: float) -> np.ndarray:
    """A state AHEAD metres in front of UAV q as `me` last heard it, flown on to k."""
    x, y, h, V, heading = heard.state[0, me, q]
    ahead = V * dt * (k - heard.stamp[0, me, q]) + AHEAD
    return np.array([x + ahead * np.cos(heading), y + ahead * np.sin(heading), h, V, heading])


def lying(what: str, scenario):
    """`agent.AgentRadio.send` with program LIAR lying about `what`, the honest send, and
    the liar's program (kept as the swarm makes it)."""
    send = agent.AgentRadio.send
    made = agent.UavAgent.__init__
    programs: dict[int, agent.UavAgent] = {}

    def keep(self, me, *args, **kwargs):
        made(self, me, *args, **kwargs)
        programs[me] = self

    def send_lies(self, k, parts, to=None):
        if self.me != LIAR:
            return send(self, k, parts, to)
        if what.startswith("tombstones"):
            parts = [
                Part(p.protocol, p.round, p.final, tombstoned(p.content, k, what != "tombstones"))
                if p.protocol == "consensus" and p.content is not None
                else p
                for p in parts
            ]
            return send(self, k, parts, to)
        if to is not None or not any(p.protocol == "beacon" for p in parts):
            return send(self, k, parts, to)
        heard = programs[LIAR].beacons
        for q in np.flatnonzero(self.links[k]):
            if q == LIAR or heard.stamp[0, LIAR, q] < 0:  # not heard yet: the truth
                send(self, k, parts, to=int(q))
                continue
            state = phantom(heard, LIAR, int(q), k, scenario.dt)
            lie = [
                Part(p.protocol, p.round, p.final, {"uav": Array.of(state)})
                if p.protocol == "beacon"
                else p
                for p in parts
            ]
            send(self, k, lie, to=int(q))
        return None

    return send, made, send_lies, keep


def lying_runs(what: str, scenario, n_trials: int) -> tuple[np.ndarray, dict[str, int]]:
    """The observation rate of each trial (seed t) of the swarm with program LIAR lying
    about `what`, and what the receivers refused, by reason, over the trials."""
    send, made, send_lies, keep = lying(what, scenario)
    agent.AgentRadio.send, agent.UavAgent.__init__ = send_lies, keep
    rates, drops = [], {}
    try:
        for t in range(n_trials):
            swarm = run_swarm(
                scenario, "distributed", seed=t, transport="memory", deadline=DEADLINE
            )
            if swarm.traffic.lost:
                raise RuntimeError(f"trial {t}: honest programs lost: {swarm.traffic.lost}")
            rates.append(swarm.result.observation_rate)
            for reason, count in swarm.traffic.drops.items():
                drops[reason] = drops.get(reason, 0) + count
    finally:
        agent.AgentRadio.send, agent.UavAgent.__init__ = send, made
    return np.array(rates), drops


def honest_rates(scenario, n_trials: int) -> np.ndarray:
    """The observation rate of each trial (seed t) of the honest team."""
    runs = [uavtrack.simulate(scenario, "distributed", seed=t) for t in range(n_trials)]
    return np.array([r.observation_rate for r in runs])


LIES = ("tombstones", "tombstones-hidden", "beacons")


def positive(text: str) -> int:
    """A count of at least 1, for argparse."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"a positive integer, got {text!r}")
    return int(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=positive, default=20)
    parser.add_argument("--steps", type=positive, default=500)
    parser.add_argument("--lie", choices=LIES, action="append", help="which (repeatable)")
    args = parser.parse_args()
    out: dict = {"trials": args.trials, "steps": args.steps}
    for what in args.lie or LIES:
        scenario = scenario_of(what, args.steps)
        honest = honest_rates(scenario, args.trials)
        liar, drops = lying_runs(what, scenario, args.trials)
        out[what] = {
            "honest": float(honest.mean()),
            "liar": float(liar.mean()),
            "liar minus honest": paired(liar, honest),
            "refused": drops,
        }
        print(json.dumps({what: out[what]}), flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
