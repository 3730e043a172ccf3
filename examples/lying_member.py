"""A member that lies within the plausibility bounds, and what the measurement gate
(``robust.gate``) does against it (docs: Faults and robustness, "A lying member").

UAV `LIAR` runs the honest program but sends, in every consensus round, a tuple per
target that passes every check of the run (`uavtrack.agents.messages.Spec`): its
estimate moved by `SHIFT` metres along x and y (folded back into the field, velocity
kept) with the most confidence the run admits: a covariance at the floor of the
sensor's accuracy (`uavtrack.robust.plausibility.Bounds.floor`) and gamma = 1 / trace of it.
With ``--lie bids`` it bids instead the largest bid the run admits for every target.
With ``--association jpda`` (or gnn) the team keeps tracks, and the liar moves every
track it offers alike; the gate then checks offered tracks against the slots a
receiver's own scans met and against its scan (`uavtrack.robust.gate.tracks_admitted`).
The lying swarm runs over the in-process transport, so each trial is the agent form
itself; the honest runs are the simulator's (the agent form equals it, seed for seed).

    python examples/lying_member.py                      # 20 trials of 500 steps
    python examples/lying_member.py --trials 4 --steps 100 --gate-memory 4
    python examples/lying_member.py --lie bids
    python examples/lying_member.py --association jpda --trials 4 --steps 200

prints, as JSON, the mean observation rate of each run and the paired differences (95%
t intervals) that matter: the liar without and with the gate against the honest team
with the same setting, and the gate's cost without a liar.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

import uavtrack
from uavtrack.agents import agent, run_swarm
from uavtrack.agents.messages import Array, Part
from uavtrack.experiments.jobs import paired
from uavtrack.robust.plausibility import Bounds

LIAR = 1
"""The lying member."""
SHIFT = 100.0
"""How far [m] the liar moves every target (along x and y, folded into the field)."""
GATE = 0.9999
"""The gate's probability in the runs with ``robust.gate``."""


def lie(content: dict[str, Array], scenario) -> dict[str, Array]:
    """A consensus tuple that passes every check of the run: each target moved by SHIFT
    along both axes (reflected at the field's walls), its covariance the floor of the
    sensor's accuracy (times 1.01), its confidence 1 / trace of that."""
    bounds = Bounds.of(scenario)
    mean = content["mean"].array().copy()
    size = scenario.field_size
    moved = np.abs((mean[:, :2] + SHIFT) % (2 * size))  # the walls are mirrors
    mean[:, :2] = np.where(moved > size, 2 * size - moved, moved)
    cov = np.broadcast_to(1.01 * bounds.floor * np.eye(4), (len(mean), 4, 4)).copy()
    out = dict(content, mean=Array.of(mean), cov=Array.of(cov))
    if "gamma" in content:  # tuples by target; tracks carry no confidence of their own
        out["gamma"] = Array.of(1.0 / np.trace(cov, axis1=-2, axis2=-1))
    return out


def bid_lie(content: dict[str, Array], scenario) -> dict[str, Array]:
    """Bids that pass every check of the run: the largest the run admits (the horizon
    times the bound of det G at the nadir, `uavtrack.robust.plausibility.Bounds.bid`), for
    every target."""
    bids = np.full(content["bids"].shape, Bounds.of(scenario).bid)
    return dict(content, bids=Array.of(bids))


LIES = {"estimates": ("consensus", lie), "bids": ("bids", bid_lie)}
"""What the liar lies about: the protocol and how."""


def lying(scenario, liar: int = LIAR, what: str = "estimates"):
    """`agent.AgentRadio.send` with program `liar` lying (`LIES`), and the honest one."""
    send = agent.AgentRadio.send
    protocol, how = LIES[what]

    def send_lies(self, k, parts, to=None):
        if self.me == liar:
            parts = [
                Part(p.protocol, p.round, p.final, how(p.content, scenario))
                if p.protocol == protocol and p.content is not None
                else p
                for p in parts
            ]
        return send(self, k, parts, to)

    return send, send_lies


def swarm_rates(scenario, n_trials: int, liar: int, what: str = "estimates") -> np.ndarray:
    """The observation rate of each trial (seed t) of the swarm with program `liar`
    lying about `what`."""
    honest, lies = lying(scenario, liar, what)
    agent.AgentRadio.send = lies
    try:
        return np.array(
            [
                run_swarm(
                    scenario, "distributed", seed=t, transport="memory"
                ).result.observation_rate
                for t in range(n_trials)
            ]
        )
    finally:
        agent.AgentRadio.send = honest


def honest_rates(scenario, n_trials: int) -> np.ndarray:
    """The observation rate of each trial (seed t) of the honest team."""
    return honest_runs(scenario, n_trials)["observation_rate"]


def honest_runs(scenario, n_trials: int) -> dict[str, np.ndarray]:
    """The observation rate and the estimation error of each trial (seed t) of the
    honest team: the RMSE with known association, the team's GOSPA with tracks."""
    runs = [uavtrack.simulate(scenario, "distributed", seed=t) for t in range(n_trials)]
    tracked = scenario.tracker.association != "known"
    return {
        "observation_rate": np.array([r.observation_rate for r in runs]),
        "error": np.array([r.gospa_best if tracked else r.rmse for r in runs]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--gate", type=float, default=GATE, help="robust.gate")
    memory = uavtrack.Scenario().robust.gate_memory
    parser.add_argument("--gate-memory", type=int, default=memory, help="robust.gate_memory")
    parser.add_argument("--lie", choices=sorted(LIES), default="estimates", help="what about")
    parser.add_argument(
        "--association", choices=("known", "gnn", "jpda"), default="known",
        help="tracker.association",
    )  # fmt: skip
    args = parser.parse_args()
    base = uavtrack.Scenario(steps=args.steps, tracker={"association": args.association})
    gated = base.with_overrides({"robust.gate": args.gate, "robust.gate_memory": args.gate_memory})
    honest = {"off": honest_runs(base, args.trials), "on": honest_runs(gated, args.trials)}
    rates = {
        "honest": honest["off"]["observation_rate"],
        "honest, robust.gate": honest["on"]["observation_rate"],
        "liar": swarm_rates(base, args.trials, LIAR, args.lie),
        "liar, robust.gate": swarm_rates(gated, args.trials, LIAR, args.lie),
    }
    out = {"lie": args.lie, "trials": args.trials, "steps": args.steps, "gate": args.gate}
    out["association"] = args.association
    out["gate_memory"] = args.gate_memory
    out["rate"] = {name: float(r.mean()) for name, r in rates.items()}
    out["liar minus honest"] = paired(rates["liar"], rates["honest"])
    out["liar minus honest, robust.gate"] = paired(
        rates["liar, robust.gate"], rates["honest, robust.gate"]
    )
    out["robust.gate minus off, honest"] = paired(rates["honest, robust.gate"], rates["honest"])
    error = "RMSE" if args.association == "known" else "GOSPA"
    out[f"robust.gate minus off, honest, {error} [m]"] = paired(
        honest["on"]["error"], honest["off"]["error"]
    )
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
