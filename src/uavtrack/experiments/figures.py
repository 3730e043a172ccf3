"""The paper's figures (Figs. 4-9) from a summary or a trace, with matplotlib.

Figs. 5-7 are grouped bar charts with standard-deviation error bars, Figs. 8-9 curves
with error bars, as in the paper; Fig. 4 is an animation written with matplotlib's
Pillow writer (no ffmpeg). Every figure is written to a temporary file and renamed.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.patches import Circle, Ellipse  # noqa: E402

from .files import replacing  # noqa: E402
from .metrics import rank_names  # noqa: E402
from .report import level_text  # noqa: E402

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


def save(fig: plt.Figure, path: Path, dpi: int = 130) -> None:
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


SERIES_STYLE = {
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


# ------------------------------------------------------------------ Fig. 4 animation


def animation_frames(steps: int, every: int) -> list[int]:
    """The steps drawn: every `every`-th, and the last one."""
    frames = list(range(0, steps, max(1, every)))
    return frames if frames[-1] == steps - 1 else frames + [steps - 1]


def _scene(trace, scenario, title: str):
    """The figure of Fig. 4 for a trace and a function that draws step k into it."""
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    from .network import adjacency
    from .sensing import observation_radius

    T, nu, nt = trace.observed.shape
    outline = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    radius = observation_radius(np.array(scenario.altitudes()), scenario.sensor)
    margin = radius.max() + 20
    lo = min(0.0, np.min(trace.uavs[..., :2])) - margin
    hi = max(scenario.field_size, np.max(trace.uavs[..., :2])) + margin
    colors = plt.cm.tab10(np.arange(nu) % 10)
    fig, ax = plt.subplots(figsize=(10, 8))
    fig.subplots_adjust(left=0.08, right=0.7, top=0.94, bottom=0.08)  # the legend on the right
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.add_patch(
        plt.Rectangle(
            (0, 0), scenario.field_size, scenario.field_size, fill=False, ls=":", color="gray"
        )
    )
    disks = [
        ax.add_patch(Circle((0, 0), radius[i], color=colors[i], alpha=0.12)) for i in range(nu)
    ]
    links = ax.add_collection(
        LineCollection([], colors="dimgray", linestyles="--", linewidths=1.0, zorder=1)
    )
    ellipses = [
        ax.add_patch(Ellipse((0, 0), 0, 0, fill=False, ls="--", color="black", lw=0.8))
        for _ in range(nt)
    ]
    targets = ax.scatter(np.zeros(nt), np.zeros(nt), c="black", s=30, zorder=4)
    names = [
        ax.annotate(
            f"T{j}",
            (0, 0),
            xytext=(5, 5),
            textcoords="offset points",
            fontsize=8,
            zorder=7,
            path_effects=outline,
        )
        for j in range(nt)
    ]
    uav_names = [
        ax.annotate(
            f"U{i}",
            (0, 0),
            xytext=(-14, -14),
            textcoords="offset points",
            fontsize=8,
            color=colors[i],
            fontweight="bold",
            zorder=7,
            path_effects=outline,
        )
        for i in range(nu)
    ]
    assigned = [ax.plot([], [], color=colors[i], lw=0.8, alpha=0.8, zorder=2)[0] for i in range(nu)]
    arrows = ax.quiver(
        np.zeros(nu),
        np.zeros(nu),
        np.ones(nu),
        np.zeros(nu),
        color=colors,
        angles="xy",
        scale_units="xy",
        scale=1,
        width=0.008,
        zorder=5,
    )
    legend = [
        Line2D(
            [], [], marker=r"$\rightarrow$", ls="", color=colors[0], ms=12, label="UAV Ui, heading"
        ),
        Circle((0, 0), 1, color=colors[0], alpha=0.2, label="observation disk"),
        Line2D([], [], color="dimgray", ls="--", label="radio link"),
        Line2D([], [], marker="o", ls="", color="black", ms=5, label="target Tj (truth)"),
        Line2D([], [], color="black", ls="--", lw=0.8, label="team's best estimate, 2\u03c3"),
        Line2D([], [], color=colors[0], lw=0.8, label="UAV to its assigned target's estimate"),
    ]
    ax.legend(handles=legend, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    heading = ax.set_title("", fontsize=10)

    def draw(k: int) -> None:
        uavs, mean, cov = trace.uavs[k], trace.mean[k], trace.cov[k]
        edges = np.argwhere(np.triu(adjacency(uavs, scenario.comm_range)))
        links.set_segments([uavs[[i, q], :2] for i, q in edges])
        best = np.argmin(np.trace(cov, axis1=-2, axis2=-1), axis=0)  # most confident UAV
        for j in range(nt):
            vals, vecs = np.linalg.eigh(cov[best[j], j, :2, :2])
            ellipses[j].set_center(mean[best[j], j, :2])
            ellipses[j].width, ellipses[j].height = 4 * np.sqrt(np.maximum(vals[::-1], 0.0))
            ellipses[j].angle = np.degrees(np.arctan2(vecs[1, 1], vecs[0, 1]))
            names[j].xy = trace.targets[k, j, :2]
        targets.set_offsets(trace.targets[k, :, :2])
        for i in range(nu):
            disks[i].set_center(uavs[i, :2])
            uav_names[i].xy = uavs[i, :2]
            j = trace.assignment[k, i]
            assigned[i].set_data([uavs[i, 0], mean[i, j, 0]], [uavs[i, 1], mean[i, j, 1]])
        points = ax.transData.transform(uavs[:, :2]) * 72.0 / fig.dpi
        for label, offset in zip(uav_names, label_offsets(points), strict=True):
            label.xyann = offset
        arrows.set_offsets(uavs[:, :2])
        arrows.set_UVC(15 * np.cos(uavs[:, 4]), 15 * np.sin(uavs[:, 4]))
        seen = trace.observed[: k + 1].any(axis=1).mean()
        heading.set_text(f"{title}, step {k}, observation rate so far {seen:.2f}")

    return fig, draw


LABEL = (18.0, 10.0)
"""The box of a UAV's label (U12) in points: width, height."""


def label_offsets(points: np.ndarray, most: int = 60) -> list[tuple[float, float]]:
    """Offsets (in points) of labels anchored at `points` (n, 2) [points], chosen so that
    no two labels overlap: each label takes the first place around its anchor, ring by
    ring, that is clear of the labels placed before it. Beyond `most` labels every one
    takes the first place (a crowd is unreadable anyway)."""
    w, h = LABEL
    rings = [(-14.0, -14.0)] + [
        (r * np.cos(a) - w / 2, r * np.sin(a) - h / 2)
        for r in (14.0, 24.0, 34.0, 46.0)
        for a in np.radians(np.arange(0, 360, 45) + 225)
    ]
    if len(points) > most:
        return [rings[0]] * len(points)
    placed: list[tuple[float, float]] = []  # lower-left corners of the placed boxes
    out = []
    for x, y in points:
        for dx, dy in rings:
            cx, cy = x + dx, y + dy
            if all(abs(cx - px) >= w or abs(cy - py) >= h for px, py in placed):
                break
        else:
            dx, dy = rings[0]
            cx, cy = x + dx, y + dy
        placed.append((cx, cy))
        out.append((float(dx), float(dy)))
    return out


def frame(trace, scenario, k: int, title: str = "") -> np.ndarray:
    """Step k of a trace drawn as `animate` draws it: an RGB array (800, 1000, 3)."""
    fig, draw = _scene(trace, scenario, title)
    try:
        draw(k)
        fig.set_dpi(100)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    finally:
        plt.close(fig)


def _drawn(fig, draw, k: int) -> np.ndarray:
    """Step k drawn into the figure, as an RGB array (H, W, 3)."""
    draw(k)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def write_gif(out, frames, fps: int, progress: Callable[[int], None] | None = None) -> int:
    """Write RGB frames (an iterable of (H, W, 3) arrays) to the binary file `out` as a
    looping GIF, each frame as it comes: memory stays that of one frame, however long the
    animation. Each frame has a 256-colour palette of its own (the first's is the
    file's). Returns the number of frames."""
    from PIL import GifImagePlugin, Image

    count = 0
    duration = int(round(1000 / fps))
    for rgb in frames:
        indexed = Image.fromarray(rgb).quantize(colors=256, method=Image.Quantize.MEDIANCUT)
        if count == 0:
            header, _ = GifImagePlugin.getheader(indexed, info={"loop": 0})
            out.write(b"".join(header))
        local = {"include_color_table": True} if count else {}
        for chunk in GifImagePlugin.getdata(indexed, duration=duration, **local):
            out.write(chunk)
        count += 1
        if progress is not None:
            progress(1)
    out.write(b";")  # the trailer
    return count


def animate(
    trace,
    scenario,
    path: Path,
    every: int = 2,
    fps: int = 10,
    title: str = "",
    progress: Callable[[int], None] | None = None,
) -> int:
    """Animate a trace like the paper's Fig. 4; returns the number of frames.

    UAVs (numbered from 0) are arrows along their heading, each in its own colour with
    its observation disk; radio links are dashed grey lines; targets (numbered from 0)
    are black dots; for each target the team's most confident estimate is drawn with its
    2-sigma ellipse; a line in the UAV's colour joins it to its estimate of its assigned
    target. Frames are 1000 x 800 pixels, the legend on the right. `progress`, if given,
    is called once per frame.
    """
    fig, draw = _scene(trace, scenario, title)
    frames = animation_frames(trace.observed.shape[0], every)
    try:
        with replacing(path) as tmp, open(tmp, "wb") as out:
            write_gif(out, (_drawn(fig, draw, k) for k in frames), fps, progress)
    finally:
        plt.close(fig)
    return len(frames)
