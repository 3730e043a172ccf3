"""One drawing of a step: the field, the UAVs with their observation disks and radio
links, the targets and their paths, each UAV's estimate of its target with its
covariance ellipse; used by the environment's render, `uavtrack animate` (Fig. 4, a GIF
written with matplotlib's Pillow writer, no ffmpeg) and anything that draws a trace.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle, Ellipse, Rectangle  # noqa: E402

from .._files import replacing  # noqa: E402
from ..world import present  # noqa: E402


def animation_frames(steps: int, every: int) -> list[int]:
    """The steps drawn: every `every`-th, and the last one."""
    frames = list(range(0, steps, max(1, every)))
    return frames if frames[-1] == steps - 1 else frames + [steps - 1]


def _scene(trace, scenario, title: str):
    """The figure of Fig. 4 for a trace and a function that draws step k into it."""
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    from ..network import adjacency
    from ..sensing import observation_radius

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
        Rectangle(
            (0, 0), scenario.field_size, scenario.field_size, fill=False, ls=":", color="gray"
        )
    )
    disks = [Circle((0, 0), radius[i], color=colors[i], alpha=0.12) for i in range(nu)]
    for disk in disks:
        ax.add_patch(disk)
    links = LineCollection([], colors="dimgray", linestyles="--", linewidths=1.0, zorder=1)
    ax.add_collection(links)
    ellipses = [
        Ellipse((0, 0), 0, 0, fill=False, ls="--", color="black", lw=0.8) for _ in range(nt)
    ]
    for ellipse in ellipses:
        ax.add_patch(ellipse)
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

    here = present(trace.targets)  # (T, Nt): a target away (target.stay) is NaN

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
            names[j].set_visible(bool(here[k, j]))  # away (target.stay)
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
        so_far = here[: k + 1]
        seen = (trace.observed[: k + 1].any(axis=1) & so_far).sum() / max(so_far.sum(), 1)
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
        return _rgb(fig)
    finally:
        plt.close(fig)


def _drawn(fig: Figure, draw: Callable[[int], None], k: int) -> np.ndarray:
    """Step k drawn into the figure, as an RGB array (H, W, 3)."""
    draw(k)
    return _rgb(fig)


def _rgb(fig: Figure) -> np.ndarray:
    """The figure rendered, as an RGB array (H, W, 3)."""
    canvas = fig.canvas
    # Agg, chosen above, or an interactive backend built on it: the canvases with pixels
    assert isinstance(canvas, FigureCanvasAgg)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


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
        chunks = GifImagePlugin.getdata(indexed, duration=duration, include_color_table=count > 0)
        for chunk in chunks:
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
