"""Per-step series of the metrics (`Result.series`, the ``steps`` table): each is the
metric of its step alone, so its mean over the steps is the run's value."""

import numpy as np
import pytest

import uavtrack

MEANS = (
    "observation_rate", "rounds", "messages", "delivered", "bytes", "conflicts",
)  # fmt: skip
"""Metrics whose run value is the mean of the steps' values with or without tracks."""

KNOWN = ("ospa", "gospa", "ospa_best", "gospa_best", "nees", "nees_best")
TRACKS = (
    "gospa", "gospa_localisation", "gospa_missed", "gospa_false", "unassigned_tracks",
    "never_tracks_new", "gospa_team", "ospa2", "ospa2_team",
)  # fmt: skip
PER_TARGET = ("switches", "fragmentations", "duplicate_tracks", "stale_tracks", "never_tracks")
"""Means per target and step: with a fixed set of targets every step weighs the same."""

TRACKED = {
    "tracker.association": "jpda",
    "sensor.detection_probability": 0.9,
    "sensor.clutter_rate": 2.0,
}


@pytest.mark.parametrize(
    "overrides,names",
    [({}, MEANS + KNOWN), (TRACKED, MEANS + TRACKS + PER_TARGET)],
    ids=["known", "tracks"],
)
def test_a_series_averages_to_the_runs_value(overrides, names):
    scenario = uavtrack.Scenario(steps=73).with_overrides(overrides)
    result = uavtrack.simulate(scenario, "distributed", seed=6)
    series = uavtrack.series(result)
    for name in names:
        values = series[name]
        assert values.shape == (73,), name
        assert np.nanmean(values) == pytest.approx(getattr(result, name), rel=1e-9), name
    if "ospa2" in names:  # one value per window of 10 steps, the last one shorter
        assert np.flatnonzero(~np.isnan(series["ospa2"])).tolist() == [*range(9, 73, 10), 72]


def test_the_rate_of_a_step_counts_the_targets_present():
    """With targets that come and go, a step's rate is the share of the targets present
    that some UAV holds in view."""
    scenario = uavtrack.Scenario(steps=80).with_overrides(
        {**TRACKED, "target.stay": 15, "target.away": 5}
    )
    result = uavtrack.simulate(scenario, "distributed", seed=2)
    here = ~np.isnan(result.trace.targets[..., 0])
    in_view = result.trace.observed.any(axis=1)
    expected = (in_view & here).sum(axis=1) / here.sum(axis=1)
    assert np.allclose(uavtrack.series(result)["observation_rate"], expected, rtol=0, atol=1e-12)


def test_the_steps_table_carries_the_series_with_units(tmp_path):
    """Parquet keeps the series columns; pandas reads them back with their units."""
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    from uavtrack.io.tables import to_frames, write_table

    scenario = uavtrack.Scenario(steps=30).with_overrides(TRACKED)
    result = uavtrack.simulate(scenario, "distributed", seed=1)
    steps = to_frames(result)["steps"]
    path = tmp_path / "steps.parquet"
    write_table(steps, path)
    back = pd.read_parquet(path)
    assert np.allclose(back["gospa"], uavtrack.series(result)["gospa"], rtol=0, atol=1e-12)
    assert steps.attrs["units"]["gospa_team"] == "m"


def test_a_result_without_a_trace_has_no_series():
    result = uavtrack.simulate(uavtrack.Scenario(steps=5), seed=0, trace=False)
    with pytest.raises(ValueError, match="no trace"):
        uavtrack.series(result)
