"""Real flight, measured (`uavtrack flight`): the autopilot's bank tracking, and the
paper's comparison with every UAV a JSBSim aircraft, in calm air, wind and turbulence.

The conditions share their trials (common random numbers: the same targets, sensor
noise and starting layout), so every difference against the unicycle is paired.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Self

import numpy as np

from ..config import G, Scenario
from . import protocol
from .jobs import Job, collect, describe, difference, label_of, paired, trial_jobs, unique
from .statistics import ci, ci95, pm

JSBSIM = {"uav.dynamics": "jsbsim"}

CONDITIONS = {
    "unicycle": {},
    "jsbsim, calm": JSBSIM,
    "jsbsim, wind 5 m/s": {**JSBSIM, "wind.speed": 5.0, "wind.direction_deg": 270.0},
    "jsbsim, wind 10 m/s": {**JSBSIM, "wind.speed": 10.0, "wind.direction_deg": 270.0},
    "jsbsim, moderate turbulence": {**JSBSIM, "wind.turbulence": "moderate"},
    "jsbsim, wind 5 m/s, planner.wind": {
        **JSBSIM,
        "wind.speed": 5.0,
        "wind.direction_deg": 270.0,
        "planner.wind": True,
    },
    "jsbsim, wind 10 m/s, planner.wind": {
        **JSBSIM,
        "wind.speed": 10.0,
        "wind.direction_deg": 270.0,
        "planner.wind": True,
    },
}
"""The flight conditions: the paper's unicycle, then JSBSim's trackwing in calm air, in a
steady west wind of 5 and 10 m/s (a third and two thirds of the airspeed), and in
moderate turbulence (MIL-F-8785C, no steady wind); then the two winds again with the
remedy, a planner that knows the steady wind (`planner.wind`)."""

METHODS = ("distributed", "centralized", "greedy")


@dataclass(frozen=True)
class Profile(protocol.Profile):
    """The size of a flight run (--quick: 2 trials of 40 steps, calm air and the strong
    wind)."""

    conditions: tuple[str, ...] = tuple(CONDITIONS)

    @classmethod
    def quick(cls) -> Self:
        """A smoke-test profile: 2 trials of 40 steps, calm air and the strong wind."""
        return replace(super().quick(), conditions=("unicycle", "jsbsim, wind 10 m/s"))


def plan(base: Scenario, profile: Profile, seed: int = 0) -> dict[str, list[Job]]:
    """Every job, grouped by condition."""
    base = base.with_overrides({"steps": profile.steps})
    return {
        name: [
            job
            for method in METHODS
            for job in trial_jobs(
                base, CONDITIONS[name], method, profile.trials, profile.chunk, seed
            )
        ]
        for name in profile.conditions
    }


def summarize(
    jobs: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json: per condition and method the metrics, and the paired differences
    against the unicycle (same method) and between the methods."""
    base = base.with_overrides({"steps": profile.steps})
    data = collect(unique(j for group in jobs.values() for j in group), results)

    def metrics(condition: str, method: str) -> dict[str, np.ndarray]:
        scenario = base.with_overrides(CONDITIONS[condition])
        return data[(label_of(difference(base, scenario)), method)]

    out: dict[str, Any] = {"conditions": {}}
    for name in profile.conditions:
        rate = {m: metrics(name, m)["observation_rate"] for m in METHODS}
        entry = {
            "overrides": CONDITIONS[name],
            "methods": {m: describe(metrics(name, m)) | {"ci95": ci95(rate[m])} for m in METHODS},
            "paired": {
                "distributed - centralized": paired(rate["distributed"], rate["centralized"]),
                "distributed - greedy": paired(rate["distributed"], rate["greedy"]),
            },
        }
        if name != "unicycle" and "unicycle" in profile.conditions:
            entry["against_unicycle"] = {
                m: paired(rate[m], metrics("unicycle", m)["observation_rate"]) for m in METHODS
            }
        out["conditions"][name] = entry
    return out


def characterise(scenario: Scenario, seconds: float = 60.0, seed: int = 0) -> dict[str, Any]:
    """The autopilot of `scenario`'s aircraft (calm air), measured at JSBSim's rate.

    * step: level to +phi, the time to 63% and 95% of the step and the overshoot;
    * reversal: +phi to -phi, the same;
    * turn: the turn rate of a steady turn at +-phi against g tan(phi) / V;
    * tracking: a random sequence of the action set's bank angles, one per cycle of dt
      (as the method flies): the bank error |phi - phi_cmd| over each cycle (mean, max,
      and the mean at the cycle's end), and the altitude and airspeed excursions.
    """
    from ..flight.jsbsim import FT, Fleet, substeps

    base = scenario.with_overrides({"n_uavs": 1, "uav.altitudes": None, **JSBSIM})
    phi = math.radians(base.uav.bank_angle_deg)
    h0, v0 = base.altitudes()[0], base.uav.speed
    n = substeps(base)
    fine = base.with_overrides({"dt": base.dt / n, "uav.jsbsim_rate_hz": n / base.dt})
    start = np.array([[[100.0, 100.0, h0, v0, 0.0]]])
    alive = np.ones((1, 1), dtype=bool)

    def record(commands: np.ndarray) -> dict[str, np.ndarray]:
        """Hold each command for one JSBSim step; bank, altitude, airspeed, course."""
        fleet = Fleet(fine, [np.random.SeedSequence(seed)], start)
        uavs, rows = fleet.states(), []
        for command in commands:
            uavs = fleet.fly(uavs, np.full((1, 1), command), alive)
            rows.append(
                (
                    fleet.bank()[0, 0],
                    uavs[0, 0, 2],
                    fleet.read("velocities/vt-fps")[0, 0] * FT,
                    uavs[0, 0, 4],
                )
            )
        return dict(zip(("bank", "h", "v", "course"), np.array(rows).T, strict=True))

    h = fine.dt

    def response(begin: float, end: float, samples: np.ndarray) -> dict[str, float]:
        fraction = (samples - begin) / (end - begin)
        t = h * (1 + np.arange(len(samples)))
        return {
            "t63_s": float(t[np.argmax(fraction >= 0.63)]),
            "t95_s": float(t[np.argmax(fraction >= 0.95)]),
            "overshoot_deg": float(
                max(0.0, np.degrees(np.max((samples - end) * np.sign(end - begin))))
            ),
        }

    settle = round(10.0 / h)
    step = record(np.full(settle, phi))
    reversal_run = record(np.concatenate([np.full(settle, phi), np.full(settle, -phi)]))
    reversal = reversal_run["bank"][settle:]
    turn = {}
    for sign in (1, -1):
        run = record(np.full(round(30.0 / h), sign * phi))
        course = np.unwrap(run["course"][-round(10.0 / h) :])
        rate = float((course[-1] - course[0]) / (h * (len(course) - 1)))
        turn["left" if sign > 0 else "right"] = {
            "rate_rad_s": rate,
            "expected_rad_s": sign * G * math.tan(phi) / v0,
            "relative_error": rate / (sign * G * math.tan(phi) / v0) - 1,
        }
    rng = np.random.default_rng(seed)
    cycles = round(seconds / base.dt)
    chosen = rng.choice([-phi, 0.0, phi], size=cycles)
    commands = np.repeat(chosen, n)
    track = record(commands)
    error = np.abs(track["bank"] - commands)
    per_cycle = error.reshape(cycles, n)
    return {
        "bank_limit_deg": math.degrees(phi),
        "rate_hz": n / base.dt,
        "step": response(0.0, phi, step["bank"]),
        "reversal": response(phi, -phi, reversal),
        "turn": turn,
        "tracking": {
            "seconds": seconds,
            "mean_error_deg": float(np.degrees(error.mean())),
            "max_error_deg": float(np.degrees(error.max())),
            "end_of_cycle_error_deg": float(np.degrees(per_cycle[:, -1].mean())),
            "altitude_excursion_m": float(np.abs(track["h"] - h0).max()),
            "airspeed_excursion_m_s": float(np.abs(track["v"] - v0).max()),
        },
        "trace": {  # the first 10 s of the tracking run, for the figure
            "t": (h * (1 + np.arange(min(len(commands), round(10.0 / h))))).tolist(),
            "command_deg": np.degrees(commands[: round(10.0 / h)]).tolist(),
            "bank_deg": np.degrees(track["bank"][: round(10.0 / h)]).tolist(),
        },
    }


NAME = "flight"
"""The command, and the results folder's name."""


def figures(jobs: dict[str, list[Job]]) -> list[str]:
    """The one figure it draws."""
    return ["flight.png"]


def figure(summary: dict[str, Any], out: Path) -> None:
    """flight.png: the observation rate per condition and method (95% CI), and the bank
    angle the autopilot flies against its commands."""
    path = out / "flight.png"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5), width_ratios=(3, 2))
    names = list(summary["conditions"])
    width = 0.8 / len(METHODS)
    for k, method in enumerate(METHODS):
        means = [summary["conditions"][c]["methods"][method]["mean"] for c in names]
        half = [summary["conditions"][c]["methods"][method]["ci95"] for c in names]
        x = np.arange(len(names)) + (k - 1) * width
        left.bar(x, means, width, yerr=np.nan_to_num(half), capsize=3, label=method)
    labels = [
        "\n".join(textwrap.wrap(n.replace(",", ""), 12, break_long_words=False)) for n in names
    ]
    left.set_xticks(np.arange(len(names)), labels, fontsize=7.5)
    left.set_ylabel("observation rate")
    left.set_ylim(0, 1.12)
    left.legend(loc="upper center", ncol=3, fontsize=8)
    left.set_title("the paper's comparison under real flight (mean, 95% CI)")
    trace = summary["autopilot"]["trace"]
    right.plot(trace["t"], trace["command_deg"], drawstyle="steps-post", label="decided bank")
    right.plot(trace["t"], trace["bank_deg"], label="trackwing's bank (JSBSim)")
    right.set_xlabel("time [s]")
    right.set_ylabel("bank angle [deg] (positive: left)")
    right.legend(loc="lower right", fontsize=8)
    right.set_title("the autopilot against one decision per cycle")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(summary: dict[str, Any], scenario: Scenario, info: dict[str, Any]) -> str:
    """report.md of `uavtrack flight`."""
    auto = summary["autopilot"]
    step, rev, track = auto["step"], auto["reversal"], auto["tracking"]
    conditions = summary["conditions"]
    trials = next(iter(conditions.values()))["methods"]["distributed"]["trials"]
    out = [
        *protocol.header(
            "Real flight: the paper's method with every UAV a JSBSim aircraft",
            trials,
            "condition and method",
            scenario,
            info,
        ),  # fmt: skip
        "",
        "## The autopilot (trackwing, calm air)",
        "",
        f"Bank limit {auto['bank_limit_deg']:g} deg, JSBSim at {auto['rate_hz']:g} Hz.",
        "",
        "| response | 63% [s] | 95% [s] | overshoot [deg] |",
        "|---|---|---|---|",
        f"| level to +phi | {step['t63_s']:.2f} | {step['t95_s']:.2f} | "
        f"{step['overshoot_deg']:.1f} |",
        f"| +phi to -phi | {rev['t63_s']:.2f} | {rev['t95_s']:.2f} | {rev['overshoot_deg']:.1f} |",
        "",
        "| steady turn | turn rate [rad/s] | g tan(phi) / V [rad/s] | error |",
        "|---|---|---|---|",
        *(
            f"| {side} | {t['rate_rad_s']:+.4f} | {t['expected_rad_s']:+.4f} | "
            f"{100 * t['relative_error']:+.1f}% |"
            for side, t in auto["turn"].items()
        ),
        "",
        f"A random bank per cycle for {track['seconds']:g} s (as the method flies): bank "
        f"error mean {track['mean_error_deg']:.1f} deg, max {track['max_error_deg']:.1f} deg, "
        f"{track['end_of_cycle_error_deg']:.1f} deg at the end of a cycle on average; "
        f"altitude within {track['altitude_excursion_m']:.1f} m and airspeed within "
        f"{track['airspeed_excursion_m_s']:.2f} m/s of their setpoints.",
        "",
        "## Observation rate",
        "",
        "Mean ± std over trials; paired differences with 95% CI (same trials).",
        "",
        "| condition | distributed | centralized | greedy | distributed − centralized | "
        "distributed − greedy | distributed − its unicycle run |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, c in conditions.items():
        cells = [pm(c["methods"][m]["mean"], c["methods"][m]["std"], 3) for m in METHODS]
        cells += [ci(c["paired"][p]) for p in ("distributed - centralized", "distributed - greedy")]
        against = c.get("against_unicycle")
        cells.append(ci(against["distributed"]) if against else "")
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    out += [
        "",
        "The planner keeps the paper's unicycle model (eq. 1) in every condition; only the "
        "world flies the aircraft. With JSBSim a UAV's V is its ground speed and its heading "
        "its course over ground, as its navigation reports them.",
        "",
        "![flight](flight.png)",
        "",
    ]
    return "\n".join(out)
