"""A method that replaces the auction by a rule of its own, with known association and
with tracks alike (see uavtrack.methods, docs: Your own method).

Each UAV follows the target it believes nearest: by its own fused estimates with known
association (one per target), by its own confirmed tracks with tracks (one per team
label it holds). The bids come by column, the estimates by target or by track slot;
`Inputs.columns` maps slots to the columns' labels (`Columns.per_label`), so the same
rule serves both.

    python examples/nearest_track.py      # its observation rate beside the paper's
"""

import numpy as np

import uavtrack
from uavtrack.methods import Assigned, Distributed, register


class NearestTrack(Distributed):
    """The paper's fusion; each UAV then follows the nearest target it knows."""

    name = "nearest"

    def assign(self, inputs, fused, bids):
        mean = fused.mean  # (B, N, M, 4) by target, or (B, N, K, 4) by track slot
        if inputs.columns is not None:  # tracks: each UAV's estimate of each label's target
            mean = inputs.columns.per_label(mean)  # (B, N, L, 4), NaN where not held
        offset = mean[..., :2] - inputs.believed[..., None, :2]
        distance = np.where(np.isnan(offset[..., 0]), np.inf, np.hypot(*np.moveaxis(offset, -1, 0)))
        known = np.isfinite(distance).any(axis=-1)
        target = np.where(inputs.alive & known, np.argmin(distance, axis=-1), -1)
        B, N = target.shape
        zeros = np.zeros(B, dtype=np.int64)
        return Assigned(target=target, seconds=np.zeros((B, N)), sent=zeros, delivered=zeros)


def main() -> None:
    register(NearestTrack())  # for this process only
    seeds = [uavtrack.trial_seed(0, t) for t in range(8)]
    tracked = {
        "tracker.association": "jpda",
        "sensor.detection_probability": 0.9,
        "sensor.clutter_rate": 2.0,
    }
    for label, scenario in (
        ("known association", uavtrack.Scenario(steps=200)),
        ("tracks (jpda)", uavtrack.Scenario(steps=200).with_overrides(tracked)),
    ):
        for method in ("distributed", "nearest"):
            rates = uavtrack.run(scenario, method, seeds).metrics["observation_rate"]
            print(f"{label:18s} {method:12s} {rates.mean():.3f}")


if __name__ == "__main__":
    main()
