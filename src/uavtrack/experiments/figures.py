"""The paper's figures (Figs. 5-9) from a summary, with matplotlib.

Figs. 5-7 are grouped bar charts with standard-deviation error bars, Figs. 8-9 curves
with error bars, as in the paper (Fig. 4, the animation of a trace, is drawn by
`uavtrack.viz.scene`). Every figure is written to a temporary file and renamed.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from .._files import replacing  # noqa: E402
from ..metrics import rank_names  # noqa: E402
from .statistics import level_text  # noqa: E402

COLORS = {"distributed": "#1f77b4", "centralized": "#2ca02c", "greedy": "#d62728"}


RANK_COLORS = ["#c6dbef", "#9ecae1", "#6baed6", "#3182bd", "#08519c", "#08306b"]


def _rate_bars(mean, std) -> np.ndarray:
    """(2, n) error bars of ±1 std around rates, cut at the [0, 1] a rate lives in."""
    mean, std = _num(mean), _num(std)
    return np.stack([np.minimum(std, mean), np.minimum(std, 1.0 - mean)])


def _num(values) -> np.ndarray:
    """Numbers from a summary, null (None: not computable, e.g. a std of one trial) as NaN,
    which matplotlib leaves out."""
    return np.array([np.nan if v is None else v for v in np.atleast_1d(values)], dtype=float)


def save(fig: Figure, path: Path, dpi: int = 130) -> None:
    """Save a figure atomically."""
    try:
        with replacing(path) as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)


def _bars(
    ax,
    groups: Sequence[str],
    series: dict[str, tuple[Sequence[float], Sequence[float]]],
    colors: dict[str, str] | Sequence[str],
    rates: bool = True,
) -> None:
    """Grouped bars with error bars: series name -> (means per group, stds per group);
    the bars of rates are cut at [0, 1]."""
    n = len(series)
    width = 0.8 / n
    x = np.arange(len(groups))
    for k, (name, (mean, std)) in enumerate(series.items()):
        color = colors[name] if isinstance(colors, dict) else colors[k % len(colors)]
        ax.bar(
            x + (k - (n - 1) / 2) * width,
            _num(mean),
            width,
            yerr=_rate_bars(mean, std) if rates else _num(std),
            capsize=3,
            label=name,
            color=color,
            edgecolor="black",
            linewidth=0.5,
            error_kw={"elinewidth": 0.8},
        )
    ax.set_xticks(x, groups)
    ax.grid(axis="y", alpha=0.3)
    ax.set_axisbelow(True)


def fig5(summary: dict[str, Any], path: Path) -> None:
    """Mean (± std) observation rate per target and overall, three methods (Fig. 5)."""
    compare = summary["compare"]
    nt = len(next(iter(compare.values()))["per_target_mean"])
    groups = [f"target {j}" for j in range(nt)] + ["overall"]
    series = {
        m: (r["per_target_mean"] + [r["mean"]], r["per_target_std"] + [r["std"]])
        for m, r in compare.items()
    }
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _bars(ax, groups, series, COLORS)
    paper = summary.get("paper", {})
    for k, m in enumerate(compare):
        if m in paper:
            width = 0.8 / len(compare)
            x = nt + (k - (len(compare) - 1) / 2) * width + 0.3 * width  # beside our bar
            ax.errorbar(
                x,
                paper[m]["mean"],
                yerr=_num(paper[m]["std"]),
                fmt="D",
                mfc="white",
                mec="black",
                ecolor="gray",
                capsize=3,
                ms=6,
                label="paper (overall)" if k == 0 else None,
            )
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("observation rate")
    ax.set_title(f"Observation rate, {summary['compare']['distributed']['trials']} trials (Fig. 5)")
    ax.legend(ncols=4, loc="upper center", fontsize=8)
    save(fig, path)


def fig6(summary: dict[str, Any], path: Path) -> None:
    """Each trial's target rates sorted lowest to highest, averaged (Fig. 6)."""
    compare = summary["compare"]
    nt = len(next(iter(compare.values()))["sorted_mean"])
    series = {m: (r["sorted_mean"], r["sorted_std"]) for m, r in compare.items()}
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _bars(ax, rank_names(nt), series, COLORS)
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("observation rate")
    ax.set_xlabel("targets of each trial, sorted by their observation rate")
    ax.set_title("Sorted observation rates (Fig. 6)")
    ax.legend(ncols=3, loc="upper left", fontsize=8)
    save(fig, path)


def fig7(summary: dict[str, Any], path: Path) -> None:
    """Decision time per cycle over team sizes N UAVs vs M targets (Fig. 7)."""
    timing = summary["timing"]
    groups = [f"{n} vs {m}" for n, m in timing["grid"]]
    series = {m: (timing[m]["mean_ms"], timing[m]["std_ms"]) for m in COLORS if m in timing}
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _bars(ax, groups, series, COLORS, rates=False)
    ax.set_yscale("log")
    # labels at 1, 2 and 5 of each decade only: every minor tick labelled would overlap
    ax.yaxis.set_major_locator(matplotlib.ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    low, high = ax.get_ylim()
    ax.set_ylim(low, high * 3)  # room above the bars for the legend
    ax.set_ylabel("decision time per cycle [ms of CPU time]")
    ax.set_xlabel("UAVs vs targets")
    ax.set_title(
        "Decision time per cycle (Fig. 7): a UAV's own (distributed, greedy),\n"
        "the central node's for the whole team (centralized)",
        fontsize=10,
    )
    ax.legend(ncols=3, fontsize=8, loc="upper left")
    save(fig, path)


def curve_figure(curve: dict[str, Any], path: Path, xlabel: str, title: str) -> None:
    """Sorted-rank and average observation rates against a parameter (Figs. 8, 9)."""
    values = curve["values"]
    rows = curve["distributed"]
    nt = len(rows[0]["sorted_mean"])
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for rank, name in enumerate(rank_names(nt)):
        ax.errorbar(
            values,
            _num([r["sorted_mean"][rank] for r in rows]),
            yerr=_rate_bars(
                [r["sorted_mean"][rank] for r in rows], [r["sorted_std"][rank] for r in rows]
            ),
            marker="o",
            ms=4,
            capsize=3,
            color=RANK_COLORS[min(rank + 1, len(RANK_COLORS) - 1)],
            label=f"{name} target of each trial",
        )
    ax.errorbar(
        values,
        _num([r["mean"] for r in rows]),
        yerr=_rate_bars([r["mean"] for r in rows], [r["std"] for r in rows]),
        marker="s",
        ms=5,
        capsize=3,
        color="black",
        lw=2,
        label="average",
    )
    ax.set_ylim(0, 1.1)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("observation rate")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    save(fig, path)


def scaling_figure(cases: list[dict[str, Any]], path: Path) -> None:
    """Time per decision cycle against team size at constant density (`uavtrack bench`'s
    scaled cycle cases), log-log, with lines of slope 1 and 2 for reference."""
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    shown = []
    for method, color, marker in (
        ("distributed", "C0", "o"),
        ("centralized", "C1", "s"),
        ("greedy", "C2", "^"),
    ):
        rows = sorted(
            (c["n_uavs"], c["median_s"])
            for c in cases
            if c.get("scaled") and c.get("method") == method
        )
        if rows:
            n, t = np.array(rows, dtype=float).T
            ax.loglog(n, 1e3 * t, marker=marker, color=color, label=method)
            shown.append((n, t))
    if not shown:
        plt.close(fig)
        raise ValueError("no scaled decision-cycle cases to plot (run the bench without --quick)")
    n, t = shown[0]  # reference lines through the distributed method's largest team
    for power, style in ((1, "--"), (2, ":")):
        ax.loglog(
            n,
            1e3 * t[-1] * (n / n[-1]) ** power,
            ls=style,
            color="gray",
            lw=1,
            label=f"slope {power} (time ~ N^{power})",
        )
    ax.set_xlabel("team size N (N UAVs x N targets, constant density)")
    ax.set_ylabel("wall time per decision cycle [ms]")
    ax.set_title(
        "Cost of a cycle against team size\n(uavtrack bench: one process, BLAS on 1 thread)",
        fontsize=10,
    )
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    save(fig, path)


def reproduction_figures(summary: dict[str, Any], out: Path) -> list[Path]:
    """fig5.png ... fig9.png in `out`."""
    out = Path(out)
    fig5(summary, out / "fig5.png")
    fig6(summary, out / "fig6.png")
    fig7(summary, out / "fig7.png")
    curve_figure(
        summary["comm_range"],
        out / "fig8.png",
        "communication range r_C [m]",
        "Distributed method against the communication range (Fig. 8)",
    )
    curve_figure(
        summary["fov"],
        out / "fig9.png",
        "half field of view alpha [deg]",
        "Distributed method against the field of view (Fig. 9)",
    )
    written = [out / f"fig{k}.png" for k in range(5, 10)]
    if "sensitivity" in summary:
        sensitivity_figure(summary["sensitivity"], out / "sensitivity.png")
        written.append(out / "sensitivity.png")
    return written


def sensitivity_figure(sens: dict[str, Any], path: Path) -> None:
    """Tornado chart: the distributed − centralized and distributed − greedy differences
    (paired, 95% CI) with each assumed parameter at its low and high value, bars drawn
    from the default's difference; rows sorted by how far they move the first."""
    pairs = (
        ("distributed - centralized", sens["near_centralized"], "within 0.03 of centralized"),
        ("distributed - greedy", sens["above_greedy"], "well above greedy (≥ 0.05)"),
    )
    rows = sorted(
        sens["rows"],
        key=lambda r: max(
            abs(v[pairs[0][0]]["mean"] - sens["base"][pairs[0][0]]["mean"]) for v in r["values"]
        ),
    )
    fig, axes = plt.subplots(
        1, 2, figsize=(12, 0.55 * len(rows) + 1.8), sharey=True, layout="constrained"
    )
    y = np.arange(len(rows))
    colors = ("#6baed6", "#fd8d3c")
    for ax, (key, threshold, claim) in zip(axes, pairs, strict=True):
        base = sens["base"][key]["mean"]
        for k, row in enumerate(rows):
            two = len(row["values"]) == 2
            for j, entry in enumerate(row["values"]):
                p = entry[key]
                color = colors[j] if two else "#9467bd"
                at = k + (0.17 - 0.34 * j if two else 0.0)  # low above, high below
                ax.barh(at, p["mean"] - base, left=base, height=0.3, color=color, alpha=0.55)
                ax.errorbar(
                    p["mean"],
                    at,
                    xerr=[[p["mean"] - p["ci_low"]], [p["ci_high"] - p["mean"]]],
                    fmt="o",
                    color=color,
                    ecolor="black",
                    elinewidth=1,
                    capsize=3,
                    ms=4,
                )
                ax.annotate(
                    level_text(entry["value"]),
                    (p["ci_high"] if p["mean"] >= base else p["ci_low"], at),
                    xytext=(4 if p["mean"] >= base else -4, 0),
                    textcoords="offset points",
                    ha="left" if p["mean"] >= base else "right",
                    va="center",
                    fontsize=7,
                )
        ax.axvline(base, color="black", lw=1, label=f"defaults ({base:+.3f})")
        ax.axvline(threshold, color="#d62728", lw=1, ls="--", label=f"{claim}: {threshold:+g}")
        ax.set_xlabel(f"{key.replace(' - ', ' − ')} (paired, 95% CI)")
        ax.grid(axis="x", alpha=0.3)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2, fontsize=8)
        low, high = ax.get_xlim()
        ax.set_xlim(low - 0.1 * (high - low), high + 0.1 * (high - low))  # room for labels
    axes[0].set_yticks(y, [f"{r['field']} ({level_text(r['default'])})" for r in rows])
    axes[0].set_ylim(-0.6, len(rows) - 0.4)
    fig.suptitle(
        "Sensitivity of the conclusions: each assumed parameter at a low (blue) and a high "
        "(orange) value or another reading (purple); default in brackets; rows by how far "
        "they move distributed − centralized",
        fontsize=10,
    )
    save(fig, path)


def sweep_figure(summary: dict[str, Any], path: Path) -> None:
    """Observation rate (mean ± std) of each method against the (first) swept field; a
    grid of several fields gets a panel per combination of the other fields' values."""
    axes_values = summary.get("axes") or {summary["field"]: summary["values"]}
    fields = list(axes_values)
    first, values = fields[0], axes_values[fields[0]]
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
    x = np.asarray(values, dtype=float) if numeric else np.arange(len(values))
    span = (x.max() - x.min()) if len(x) > 1 and x.max() > x.min() else 1.0
    shape = [len(v) for v in axes_values.values()]
    panels = list(itertools.product(*(range(n) for n in shape[1:])))
    ncols = min(3, len(panels))
    nrows = -(-len(panels) // ncols)
    size = (8, 4.5) if len(panels) == 1 else (4.6 * ncols, 3.6 * nrows + 0.6)
    fig, grid = plt.subplots(nrows, ncols, figsize=size, squeeze=False, sharey=True)
    n = len(summary["methods"])
    units = summary.get("units") or {first: summary.get("unit")}
    for ax, rest in zip(grid.flat, panels, strict=False):
        cells = [int(np.ravel_multi_index((i, *rest), shape)) for i in range(len(values))]
        for k, (m, rows) in enumerate(summary["methods"].items()):
            ax.errorbar(
                x + (k - (n - 1) / 2) * 0.01 * span,  # side by side, so the bars show
                _num([rows[c]["mean"] for c in cells]),
                yerr=_num([rows[c]["std"] for c in cells]),
                marker="o",
                capsize=3,
                label=m,
                color=COLORS.get(m),
            )
        if not numeric:
            ax.set_xticks(x, [level_text(v) for v in values])
        unit = units.get(first)
        ax.set_xlabel(f"{first} [{unit}]" if unit else first)
        ax.set_ylim(0, 1.05)
        ax.grid(alpha=0.3)
        if rest:
            ax.set_title(
                ", ".join(
                    f"{f}={level_text(axes_values[f][r])}"
                    for f, r in zip(fields[1:], rest, strict=True)
                ),
                fontsize=9,
            )
    for ax in grid.flat[len(panels) :]:
        ax.set_visible(False)
    for ax in grid[:, 0]:
        ax.set_ylabel("observation rate (mean ± std)")
    grid.flat[0].legend()
    fig.suptitle(f"Sweep of {' × '.join(fields)}")
    save(fig, path)


class _Style(TypedDict, total=False):
    """How a series is drawn: matplotlib's line properties of that name."""

    color: str
    marker: str
    ls: str
    label: str


SERIES_STYLE: dict[str, _Style] = {
    "distributed": {"color": COLORS["distributed"], "marker": "o", "label": "distributed (paper)"},
    "robust": {
        "color": "#9467bd",
        "marker": "D",
        "ls": "--",
        "label": "distributed, robust options on",
    },
    "centralized": {"color": COLORS["centralized"], "marker": "s", "label": "centralized"},
    "greedy": {"color": COLORS["greedy"], "marker": "^", "label": "greedy"},
}


def fault_figure(name: str, fault: dict[str, Any], path: Path) -> None:
    """Observation rate against one fault's level, a line per series, 95% intervals."""
    levels = fault["levels"]
    x = np.arange(len(levels))  # the levels evenly spaced, named on the axis
    fig, ax = plt.subplots(figsize=(8, 5))
    n = len(fault["series"])
    for k, (series, rows) in enumerate(fault["series"].items()):
        style = SERIES_STYLE.get(series, {"label": series})
        ax.errorbar(
            x + (k - (n - 1) / 2) * 0.06,  # side by side, so the intervals show
            _num([r["mean"] for r in rows]),
            yerr=_num([r["ci95"] for r in rows]),
            capsize=3,
            ms=5,
            **style,
        )
    ax.set_xticks(x, [level_text(v) for v in levels])
    ax.set_xlabel(fault["xlabel"])
    ax.set_ylabel("observation rate (mean, 95% CI)")
    ax.set_ylim(0, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncols=4)
    fixed = ", ".join(f"{k} = {v}" for k, v in fault.get("fixed", {}).items())
    ax.set_title(f"Fault: {name}" + (f" ({fixed})" if fixed else ""))
    save(fig, path)


def robustness_figures(summary: dict[str, Any], out: Path) -> list[Path]:
    """fault_<name>.png in `out`, one per fault."""
    paths = []
    for name, fault in summary["faults"].items():
        path = Path(out) / f"fault_{name}.png"
        fault_figure(name, fault, path)
        paths.append(path)
    return paths
