import numpy as np
import pytest
from PIL import Image

import uavtrack
from uavtrack.experiments import figures
from uavtrack.viz import scene


@pytest.fixture
def kept(monkeypatch):
    """Figures handed to figures.save, kept open for inspection instead of written."""
    drawn = []
    monkeypatch.setattr(figures, "save", lambda fig, path, dpi=130: drawn.append(fig))
    yield drawn
    for fig in drawn:
        figures.plt.close(fig)


def timing_summary():
    grid = [[3, 2], [5, 4], [8, 6], [10, 10], [20, 20]]
    rng = np.random.default_rng(0)
    out = {"timing": {"grid": grid, "steps": 100, "trials": 3}}
    for m, scale in (("distributed", 0.05), ("centralized", 0.3), ("greedy", 0.02)):
        mean = scale * np.geomspace(1, 4, len(grid)) * rng.uniform(0.8, 1.2, len(grid))
        out["timing"][m] = {"mean_ms": mean.tolist(), "std_ms": (0.1 * mean).tolist()}
    return out


def overlapping(labels):
    boxes = [t.get_window_extent() for t in labels if t.get_text()]
    return [(a, b) for k, a in enumerate(boxes) for b in boxes[k + 1 :] if a.overlaps(b)]


def test_fig7_tick_labels_do_not_overlap(kept):
    figures.fig7(timing_summary(), "unused.png")
    fig = kept[0]
    fig.canvas.draw()
    ax = fig.axes[0]
    labels = ax.get_yticklabels(minor=False) + ax.get_yticklabels(minor=True)
    assert len([t for t in labels if t.get_text()]) >= 2
    assert not overlapping(labels)
    # the legend sits above the bars
    legend = ax.get_legend().get_window_extent()
    for bar in ax.patches:
        assert not legend.overlaps(bar.get_window_extent())


def test_sweep_axis_names_the_unit(kept):
    summary = {
        "field": "comm_range",
        "unit": "m",
        "values": [10.0, 50.0],
        "methods": {"distributed": [{"mean": 0.6, "std": 0.1}, {"mean": 0.7, "std": None}]},
    }
    figures.sweep_figure(summary, "unused.png")
    assert kept[0].axes[0].get_xlabel() == "comm_range [m]"


def test_fig5_numbers_targets_from_zero(kept):
    row = {
        "per_target_mean": [0.5] * 3,
        "per_target_std": [0.1] * 3,
        "mean": 0.5,
        "std": 0.1,
        "trials": 2,
    }
    figures.fig5({"compare": {"distributed": row}}, "unused.png")
    names = [t.get_text() for t in kept[0].axes[0].get_xticklabels()]
    assert names == ["target 0", "target 1", "target 2", "overall"]


def test_animation_frames_legend_and_link_colour(tmp_path, monkeypatch):
    scenario = uavtrack.Scenario(steps=6)
    trace = uavtrack.simulate(scenario, seed=0).trace
    legends = []
    real_legend = figures.plt.Axes.legend

    def keep(ax, *args, **kwargs):
        legends.append(kwargs.get("handles"))
        return real_legend(ax, *args, **kwargs)

    monkeypatch.setattr(figures.plt.Axes, "legend", keep)
    frames = []
    n = scene.animate(trace, scenario, tmp_path / "a.gif", every=2, progress=frames.append)
    assert n == 4 and len(frames) == 4  # steps 0, 2, 4 and the last, 5
    with Image.open(tmp_path / "a.gif") as im:
        assert im.size == (1000, 800) and im.n_frames == 4
    labels = [h.get_label() for h in legends[0]]
    assert "radio link" in labels and "observation disk" in labels
    link = next(h for h in legends[0] if h.get_label() == "radio link")
    uav0 = figures.plt.cm.tab10(0)
    assert link.get_color() == "dimgray" and link.get_color() != uav0


def test_uav_labels_never_overlap_even_when_the_uavs_do():
    # the first frame of the default scenario: all five UAVs start within metres
    for points in (np.zeros((5, 2)), np.array([[0, 0], [3, 1], [1, 4], [5, 5], [2, 2.0]])):
        offsets = np.asarray(scene.label_offsets(points))
        boxes = points + offsets
        w, h = scene.LABEL
        for a in range(len(boxes)):
            for b in range(a):
                dx, dy = np.abs(boxes[a] - boxes[b])
                assert dx >= w or dy >= h, (a, b)


def test_a_gif_is_written_frame_by_frame(tmp_path):
    # frames come from a generator and are written as they come: a frame drawn before
    # the previous one was written would show in the order of these calls
    made, written = [], []
    colours = [(255, 0, 0), (0, 128, 0), (0, 0, 255)]

    def frames():
        for k, colour in enumerate(colours):
            made.append(k)
            assert written == list(range(k))  # everything before was written already
            yield np.full((20, 30, 3), colour, dtype=np.uint8)

    with open(tmp_path / "x.gif", "wb") as out:
        n = scene.write_gif(out, frames(), fps=5, progress=lambda _: written.append(len(written)))
    assert n == 3
    with Image.open(tmp_path / "x.gif") as im:
        assert im.n_frames == 3 and im.info["duration"] == 200 and im.info["loop"] == 0
        for k, colour in enumerate(colours):
            im.seek(k)
            assert im.convert("RGB").getpixel((10, 10)) == colour
