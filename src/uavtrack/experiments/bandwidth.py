"""A radio with a byte budget (`uavtrack bandwidth`): the observation rate of the three
methods against the channel's capacity (``radio.bandwidth_bps``, 1 kbit/s to 1 Mbit/s and
unlimited), the distributed and greedy methods also with the compact encoding
(``radio.encoding``), the event trigger (``fusion.trigger``) and both, with one frame per
round to all receivers (``radio.frames``), and with the smallest messages: one frame to
all, the quantized encoding and the trigger.

Every cell runs the same trials (common random numbers), so each is paired trial by trial
with its method's unlimited run of the paper's exchange. The bytes are those the agent
form puts on the wire (`radio.frame_bytes`), per UAV and step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Scenario
from . import protocol
from .jobs import Job, collect, difference, label_of, trial_jobs, unique
from .statistics import ci95, describe, paired

METHODS = ("distributed", "centralized", "greedy")
BANDWIDTHS = (None, 1e3, 3e3, 1e4, 3e4, 1e5, 3e5, 1e6)
"""The channel capacities [bit/s] (None: unlimited)."""
TRIGGER = 0.1
"""The event trigger of the variants that have one: a target's tuple is sent again when its
confidence moved by a tenth since it was last sent. Assumed: between the 0 that sends all
and a half, which leaves most of the consensus out; measured against none here."""
VARIANTS = {
    "paper": {},
    "compact": {"radio.encoding": "compact"},
    "trigger": {"fusion.trigger": TRIGGER},
    "both": {"radio.encoding": "compact", "fusion.trigger": TRIGGER},
    "broadcast": {"radio.frames": "broadcast"},
    "smallest": {
        "radio.frames": "broadcast",
        "radio.encoding": "quantized",
        "fusion.trigger": TRIGGER,
    },
}
"""How the consensus is sent: the paper's exchange, and the ways to send less."""
SCORED = ("observation_rate", "bytes", "messages", "rmse_best", "ospa_best", "nees_inside")
"""The metrics the summary keeps per cell (mean and std over the trials)."""

CUT = 0.60
"""The goal: bytes per UAV and step cut by at least this by the encoding and the trigger."""
COST = 0.01
"""... at a paired cost in observation rate of at most this."""
SMALLEST_CUT = 0.75
"""The goal: bytes per UAV and step cut by at least this by the smallest messages (one
frame to all, quantized, trigger), at a cost of at most `COST` ..."""
NEES_GAP = 0.02
"""... and the fraction of NEES samples inside the 95 % interval within this of the
paper's exchange."""
KEEP = 0.95
"""The fraction of its unlimited observation rate a method must keep at the bandwidth
quoted for it."""


@dataclass(frozen=True)
class Profile(protocol.Profile):
    """The size of a bandwidth run (--quick: 2 trials of 40 steps)."""


def variants(method: str) -> list[str]:
    """The variants a method runs: the centralized method uploads and downloads whole
    tables, which the encoding and the trigger do not act on."""
    return ["paper"] if method == "centralized" else list(VARIANTS)


def overrides(variant: str, bandwidth: float | None) -> dict[str, Any]:
    """The fields of one cell against the base."""
    out = dict(VARIANTS[variant])
    if bandwidth is not None:
        out["radio.bandwidth_bps"] = bandwidth
    return out


def cells(method: str) -> list[tuple[str, float | None]]:
    """Every (variant, bandwidth) of a method."""
    return [(v, b) for v in variants(method) for b in BANDWIDTHS]


def plan(base: Scenario, profile: Profile, seed: int = 0) -> dict[str, list[Job]]:
    """Every job, grouped by method."""
    base = base.with_overrides({"steps": profile.steps})
    return {
        method: [
            job
            for variant, bandwidth in cells(method)
            for job in trial_jobs(
                base, overrides(variant, bandwidth), method, profile.trials, profile.chunk, seed
            )
        ]
        for method in METHODS
    }


def name(bandwidth: float | None) -> str:
    """A capacity as the report writes it (1 kbit/s, 300 kbit/s, 1 Mbit/s, unlimited)."""
    if bandwidth is None:
        return "unlimited"
    if bandwidth >= 1e6:
        return f"{bandwidth / 1e6:g} Mbit/s"
    return f"{bandwidth / 1e3:g} kbit/s"


def summarize(
    jobs: dict[str, list[Job]], results: dict[str, dict], profile: Profile, base: Scenario
) -> dict[str, Any]:
    """summary.json: per method, variant and capacity the metrics, each paired with the
    method's unlimited run of the paper's exchange; the capacity that keeps 95 % of it;
    and the goals."""
    base = base.with_overrides({"steps": profile.steps})
    data = collect(unique(j for group in jobs.values() for j in group), results)

    def metrics(method: str, variant: str, bandwidth: float | None) -> dict:
        scenario = base.with_overrides(overrides(variant, bandwidth))
        return data[(label_of(difference(base, scenario)), method)]

    out: dict[str, Any] = {"methods": {}, "bandwidths": [name(b) for b in BANDWIDTHS]}
    out["bits_per_second"] = [b for b in BANDWIDTHS]
    for method in METHODS:
        reference = metrics(method, "paper", None)
        rows: dict[str, Any] = {}
        for variant in variants(method):
            row: dict[str, Any] = {}
            for bandwidth in BANDWIDTHS:
                m = metrics(method, variant, bandwidth)
                d = describe(m)
                cell: dict[str, Any] = {"trials": d["trials"], "ci95": ci95(m["observation_rate"])}
                for field in SCORED:
                    cell[field] = (
                        {"mean": d["mean"], "std": d["std"]}
                        if field == "observation_rate"
                        else d[field]
                    )
                cell["cost"] = paired(reference["observation_rate"], m["observation_rate"])
                row[name(bandwidth)] = cell
            unlimited = row["unlimited"]["observation_rate"]["mean"]
            row["keeps"] = keeps(row, unlimited)
            rows[variant] = row
        out["methods"][method] = rows
    out["goals"] = goals(out)
    return out


def keeps(row: dict[str, Any], unlimited: float) -> str | None:
    """The smallest capacity of the grid from which on the variant keeps `KEEP` of its
    own unlimited rate at every larger capacity (None: none of the limited ones)."""
    found = None
    for bandwidth in reversed(BANDWIDTHS[1:]):
        if row[name(bandwidth)]["observation_rate"]["mean"] >= KEEP * unlimited:
            found = name(bandwidth)
        else:
            break
    return found


def goals(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The goals for the distributed method, unlimited: the bytes the encoding and the
    trigger cut together, at their cost; and every method's 95 % capacity (reported)."""
    rows = summary["methods"]["distributed"]
    paper, both = rows["paper"]["unlimited"], rows["both"]["unlimited"]
    smallest = rows["smallest"]["unlimited"]

    def cut(cell: dict[str, Any]) -> float:
        spent = paper["bytes"]["mean"]
        return 1.0 - cell["bytes"]["mean"] / spent if spent else 0.0

    gap = abs(smallest["nees_inside"]["mean"] - paper["nees_inside"]["mean"])
    out = [
        ("distributed: bytes per UAV and step cut by compact + trigger", cut(both), ">=", CUT),
        ("distributed: their cost in observation rate (paired)", both["cost"]["mean"], "<=", COST),
        ("distributed: bytes cut by the smallest messages (one frame to all, quantized, "
         "trigger)", cut(smallest), ">=", SMALLEST_CUT),
        ("distributed: their cost in observation rate (paired)", smallest["cost"]["mean"],
         "<=", COST),
        ("distributed: their NEES inside its 95% interval, distance from the paper's "
         "exchange", gap, "<=", NEES_GAP),
    ]  # fmt: skip
    rows_out = [
        {"goal": goal, "value": value, "op": op, "bound": bound,
         "met": bool(np.isfinite(value) and (value >= bound if op == ">=" else value <= bound))}
        for goal, value, op, bound in out
    ]  # fmt: skip
    grid = [name(b) for b in BANDWIDTHS]
    for method in METHODS:
        paper = summary["methods"][method]["paper"]
        found = paper["keeps"]
        value = math.nan if found is None else BANDWIDTHS[grid.index(found)]
        alone = alone_rate(paper)
        need = KEEP * paper["unlimited"]["observation_rate"]["mean"]
        rows_out.append({
            "goal": f"{method}: capacity keeping 95% of its unlimited rate", "value": value,
            "op": "found", "bound": need, "alone": alone,
            # found, and the radio is what keeps it: without one the rate is below
            "met": bool(found is not None and (alone is None or alone < need)),
        })  # fmt: skip
    return rows_out


def alone_rate(row: dict[str, Any]) -> float | None:
    """The rate without a radio: at the smallest capacity when nothing fits in it (None
    when something does)."""
    least = row[name(BANDWIDTHS[1])]
    return least["observation_rate"]["mean"] if least["bytes"]["mean"] == 0 else None


NAME = "bandwidth"
"""The command, and the results folder's name."""


def figures(jobs: dict[str, list[Job]]) -> list[str]:
    """The one figure it draws."""
    return ["bandwidth.png"]


def figure(summary: dict[str, Any], out: Path) -> None:
    """bandwidth.png: the observation rate (95 % CI) and the bytes per UAV and step of
    each method and variant against the capacity; the unlimited value at the right."""
    path = out / "bandwidth.png"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    limited = [b for b in BANDWIDTHS if b is not None]
    x = np.array([*limited, limited[-1] * 4.0])  # unlimited drawn one step beyond
    colours = {"distributed": "tab:blue", "centralized": "tab:green", "greedy": "tab:red"}
    styles = {
        "paper": "-", "compact": "--", "trigger": ":", "both": "-.",
        "broadcast": (0, (5, 1, 1, 1, 1, 1)), "smallest": (0, (1, 3)),
    }  # fmt: skip
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for method, rows in summary["methods"].items():
        for variant, row in rows.items():
            cells = [row[name(b)] for b in (*limited, None)]
            rate = [c["observation_rate"]["mean"] for c in cells]
            err = [c["ci95"] for c in cells]
            load = [max(c["bytes"]["mean"], 1.0) for c in cells]
            style: dict[str, Any] = {"color": colours[method], "linestyle": styles[variant]}
            style["zorder"] = 3 if method == "centralized" else 2
            axes[0].errorbar(x, rate, yerr=err, capsize=2, marker="o", ms=3,
                             label=f"{method}, {variant}", **style)  # fmt: skip
            axes[1].plot(x, load, marker="o", ms=3, label=f"{method}, {variant}", **style)
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xticks(x, [name(b).replace(" ", "\n") for b in (*limited, None)], fontsize=7)
        ax.set_xlabel("channel capacity (shared: each UAV's neighbourhood; centralized, all)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("observation rate (95% CI)")
    axes[0].set_ylim(0.0, 1.05)
    axes[0].legend(fontsize=7, ncol=2, loc="lower right")
    axes[1].set_ylabel("radio bytes per UAV and step (1 drawn for 0)")
    axes[1].set_yscale("log")
    axes[1].legend(fontsize=7, ncol=2, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(summary: dict[str, Any], scenario: Scenario, info: dict[str, Any]) -> str:
    """report.md of `uavtrack bandwidth`."""
    first = summary["methods"]["distributed"]["paper"]["unlimited"]
    out = [
        *protocol.header(
            "Bandwidth: a radio with a byte budget",
            first["trials"],
            "cell and method",
            scenario,
            info,
        ),  # fmt: skip
        "",
        f"The channel's capacity is shared: each UAV gets capacity x dT / 8 bytes a cycle "
        f"(dT = {scenario.dt:g} s) over its closed neighbourhood (with the centralized "
        "method, over every UAV and the central node); what does not fit is not sent, in "
        "the order: the beacon with the bids (the upload), then the rounds of D_i flooding "
        "and consensus, each reserved at its largest, the node's downloads in UAV order "
        "(`radio.Budget`). Bytes are the agent form's frames on the wire, per UAV and step. "
        f"Variants: compact = `radio.encoding=compact`; trigger = `fusion.trigger={TRIGGER}` "
        "(refresh every 10 cycles); both; broadcast = `radio.frames=broadcast` (one frame "
        "per round to all receivers); smallest = broadcast with `radio.encoding=quantized` "
        "and the trigger. Cost = the method's unlimited paper rate minus the cell's, paired "
        "trial by trial. NEES inside: the fraction of NEES samples (every UAV's fused "
        "estimate) inside the 95% chi-square(4) interval.",
        "",
        "## Goals",
        "",
        "| goal | measured | bound | met |",
        "|---|---|---|---|",
    ]
    for g in summary["goals"]:
        value = g["value"]
        if g["op"] == "found":
            shown = "none in the grid" if not np.isfinite(value) else name(value)
            bound = f"found; without a radio below {g['bound']:.3f}"
            if g["alone"] is not None:
                bound += f" (it is {g['alone']:.3f})"
        else:
            shown, bound = f"{value:.4g}", f"{g['op']} {g['bound']:g}"
        out.append(f"| {g['goal']} | {shown} | {bound} | {'yes' if g['met'] else '**no**'} |")
    out.append("")
    for method, rows in summary["methods"].items():
        out += [
            f"## {method}",
            "",
            "| variant | capacity | rate (95% CI) | cost (95% CI) | bytes per UAV and step "
            "| NEES inside |",
            "|---|---|---|---|---|---|",
        ]
        for variant, row in rows.items():
            for bandwidth in BANDWIDTHS:
                c = row[name(bandwidth)]
                cost = c["cost"]
                out.append(
                    f"| {variant} | {name(bandwidth)} | "
                    f"{c['observation_rate']['mean']:.3f} ± {c['ci95']:.3f} | "
                    f"{cost['mean']:+.3f} ({cost['ci_low']:+.3f}, {cost['ci_high']:+.3f}) | "
                    f"{c['bytes']['mean']:.0f} | {c['nees_inside']['mean']:.3f} |"
                )
        keeps_ = ", ".join(f"{v}: {row['keeps'] or 'none'}" for v, row in rows.items())
        out += ["", f"Capacity from which each variant keeps 95 % of its unlimited rate: "
                f"{keeps_}.", ""]  # fmt: skip
        alone = alone_rate(rows["paper"])
        if alone is not None:  # nothing fits: the rate without a radio
            need = KEEP * rows["paper"]["unlimited"]["observation_rate"]["mean"]
            verdict = (
                "already at 95 % of the unlimited paper rate "
                f"({need:.3f}): the radio adds less than 5 %, and 95 % says little here"
                if alone >= need
                else f"below 95 % of the unlimited paper rate ({need:.3f})"
            )
            out += [f"Without a radio ({name(BANDWIDTHS[1])} carries nothing) the rate is "
                    f"{alone:.3f}, {verdict}.", ""]  # fmt: skip
    out += ["![bandwidth](bandwidth.png)", ""]
    return "\n".join(out)
