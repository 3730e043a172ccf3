"""uavtrack's central tracker against Stone Soup's JPDA and GNN multi-target trackers on
the very scans of a centralized run, scored alike.

    python benchmarks/trackers.py [--trials 4] [--steps 500] [--association jpda]
        [--clutter 2] [--detection 0.9] [--out FILE]

For each trial, a centralized run with tracks (``tracker.association``) is made with its
trace; its scans (each UAV's, in UAV order, as the central node takes them) are fed

* to uavtrack's central tracker again (`tracks.manage.scan`, replayed outside the run:
  the replay must give the run's tracks, which the script checks, and times the tracker
  alone), and
* to a Stone Soup tracker built from Stone Soup's own parts: ``MultiTargetMixtureTracker``
  with ``JPDA`` and ``PDAHypothesiser`` (or ``MultiTargetTracker`` with
  ``GNNWith2DAssignment`` and ``DistanceHypothesiser`` for gnn: Mahalanobis distance,
  which reads neither P_D nor the clutter), Kalman predictor and updater, a
  ``MultiMeasurementInitiator`` (M updates to confirm, M of ``tracker.confirm``).

Both use the same models: the targets' constant-velocity motion with the run's process
noise Q (eq. 15), each measurement's converted position with its covariance R (eqs.
5-12, from the UAV's pose), the clutter density (clutter per scan over the observation
disk), P_D where a track is predicted in the scanning UAV's disk (widened by 3 std of the
track's position) and 0 elsewhere, P_G and its gate. Both start from the briefing (every
target a confirmed track), or with no track under ``tracker.briefing = false``. Stone
Soup's tracker has no existence probability: it confirms and deletes by the project's
M-of-N rules (uavtrack's under ``tracker.confirmation = "m_of_n"``): a confirmed track
after ``tracker.delete_misses`` scans in view in a row without an update, or when its
position std exceeds ``tracker.delete_std``; a tentative one when it can no longer meet
M of N (``tracker.confirm``).

Each step's confirmed tracks after the last scan are scored against the truth: GOSPA
(c 20 m, p 1, alpha 2) and its parts (`tracks.scoring.gospa_assignment`), duplicates
(confirmed tracks beyond the first whose nearest truth within c is the same target) and
tracks that never followed a target, per target and step. CPU per scan is
``time.process_time`` over the replay divided by the scans (UAV x step), one process.
Prints a table and writes no file; ``--out FILE`` keeps the numbers as JSON.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import uavtrack
from uavtrack import _files, estimation, sensing, simulation
from uavtrack.cli.app import parse_overrides
from uavtrack.errors import ScenarioError, UsageError
from uavtrack.tracks import manage
from uavtrack.tracks.scoring import gospa_assignment

CUTOFF, ORDER = 20.0, 1.0
ORDER_SS = [0, 2, 1, 3]  # uavtrack (x, y, vx, vy) in Stone Soup's (x, vx, y, vy)
EPOCH = dt.datetime(2000, 1, 1)
TICK = dt.timedelta(microseconds=1)  # UAV i's scan of step k comes at t_k + i ticks


OWN = {
    "steps": "--steps",
    "sensor.detection_probability": "--detection",
    "sensor.clutter_rate": "--clutter",
    "tracker.association": "--association",
}
"""The settings the script's own options give: --set may not give them too."""


def scenario(args: argparse.Namespace) -> uavtrack.Scenario:
    """The run's scenario: the script's options, then --set (values as `uavtrack run
    --set` reads them, TOML). Raises ScenarioError on a bad setting."""
    more = parse_overrides(args.set)
    for key, option in OWN.items():
        if key in more:
            raise ScenarioError(f"--set {key}: give it with {option}")
    return uavtrack.Scenario().with_overrides(
        {
            "steps": args.steps,
            "sensor.detection_probability": args.detection,
            "sensor.clutter_rate": args.clutter,
            "tracker.association": args.association,
            **more,
        }
    )


# ------------------------------------------------------------------ the scans of a run


def scans(sc: uavtrack.Scenario, trace) -> list[list[tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """Per step, per UAV: (z (Z, 2), R (Z, 2, 2), origin (Z,)) of its scan, R from its pose."""
    out = []
    for k in range(sc.steps):
        step = []
        for i in range(sc.n_uavs):
            ok = trace.scan_valid[k, i]
            polar = trace.scan_polar[k, i][ok]
            pose = np.broadcast_to(trace.uavs[k, i], (len(polar), trace.uavs.shape[-1]))
            z, R = simulation.convert(pose, polar, sc)
            step.append((z, R, trace.scan_origin[k, i][ok]))
        out.append(step)
    return out


# ------------------------------------------------------------------ uavtrack, replayed


def replay_uavtrack(sc: uavtrack.Scenario, seed: int, trace, scanned) -> tuple[list, float]:
    """The central tracker on the run's scans: per step (mean (K, 4), label, confirmed)."""
    state = simulation.initial_state(sc, [seed])[0]
    node = state.central
    tracker = estimation.Tracker.of(sc.dt, sc.acceleration_std(), sc.tracker)
    K = node.book.label.shape[-1]
    out = []
    start = time.process_time()
    for k in range(sc.steps):
        for i in range(sc.n_uavs):
            z, R, _ = scanned[k][i]
            Z = max(len(z), 1)
            zz, RR = np.zeros((1, 1, Z, 2)), np.broadcast_to(np.eye(2), (1, 1, Z, 2, 2)).copy()
            valid = np.zeros((1, 1, Z), bool)
            zz[0, 0, : len(z)], RR[0, 0, : len(z)], valid[0, 0, : len(z)] = z, R, True
            s = manage.scan(
                node.book, node.mean, node.cov, zz, RR, valid, trace.uavs[k, i][None, None],
                np.ones((1, 1), bool), sc, node.modes, tracker, k,
            )  # fmt: skip
            node = manage.Slots(book=s.book, mean=s.mean, cov=s.cov, modes=s.modes)
        out.append(
            (node.mean[0, 0].copy(), node.book.label[0, 0].copy(), node.book.confirmed[0, 0].copy())
        )
        m, P, modes = tracker.close(node.mean, node.cov, node.modes, node.mean, node.cov)
        node = manage.Slots(book=manage.survive(node.book, sc), mean=m, cov=P, modes=modes)
    cpu = time.process_time() - start
    for k in range(sc.steps):  # the replay is the run
        mean, label, confirmed = out[k]
        held = trace.status[k, 0] == manage.CONFIRMED
        if not (np.array_equal(held, confirmed) and np.array_equal(trace.label[k, 0], label)):
            raise SystemExit(f"the replay left the run at step {k}")
        if not np.allclose(trace.mean[k, 0][held], mean[held], atol=1e-6):
            raise SystemExit(f"the replay's estimates left the run's at step {k}")
    assert K == len(out[0][1])
    return out, cpu


# ------------------------------------------------------------------ Stone Soup


def stonesoup_tracker(sc: uavtrack.Scenario, seed: int, trace, scanned, association: str):
    """Stone Soup's tracker on the run's scans: per step (mean (n, 4), ids, all confirmed)."""
    from scipy.stats import chi2
    from stonesoup.base import Property
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.deleter.base import Deleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import LinearGaussianTransitionModel
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.tracker.simple import MultiTargetMixtureTracker, MultiTargetTracker
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.types.update import Update
    from stonesoup.updater.kalman import KalmanUpdater

    settings, sensor = sc.tracker, sc.sensor
    F = estimation.transition(sc.dt)[np.ix_(ORDER_SS, ORDER_SS)]
    Q = estimation.process_noise(sc.dt, *sc.acceleration_std())[np.ix_(ORDER_SS, ORDER_SS)]

    class StepTransition(LinearGaussianTransitionModel):
        """uavtrack's motion over whole steps; the scans of one step share its time."""

        step: float = Property(doc="dT [s]")

        @property
        def ndim_state(self):
            return 4

        def _n(self, time_interval):
            return round(time_interval.total_seconds() / self.step)

        def matrix(self, time_interval=None, **kwargs):
            return np.linalg.matrix_power(F, self._n(time_interval))

        def covar(self, time_interval=None, **kwargs):
            Qn = np.zeros((4, 4))
            for _ in range(self._n(time_interval)):
                Qn = F @ Qn @ F.T + Q
            return Qn

    view = {"uav": None}  # the scanning UAV's pose
    seen: dict = {}  # track -> predicted in the scanning UAV's (widened) disk

    def in_view(prediction) -> bool:
        pose = view["uav"]
        x, y = prediction.state_vector[0, 0], prediction.state_vector[2, 0]
        spread = 3 * np.sqrt(prediction.covar[0, 0] + prediction.covar[2, 2])
        r = float(sensing.observation_radius(pose[2], sensor))
        return (x - pose[0]) ** 2 + (y - pose[1]) ** 2 <= (r + spread) ** 2

    radius = float(sensing.observation_radius(np.asarray(sc.uav.altitude), sensor))
    density = max(sensor.clutter_rate, 1e-3) / (np.pi * radius**2)
    predictor = KalmanPredictor(StepTransition(step=sc.dt))
    updater = KalmanUpdater(measurement_model=None)

    class ViewPDA(PDAHypothesiser):
        def hypothesise(self, track, detections, timestamp, **kwargs):
            prediction = self.predictor.predict(track, timestamp=timestamp)
            seen[track] = inside = in_view(prediction)
            self.prob_detect = sensor.detection_probability if inside else 1e-9
            return super().hypothesise(track, detections, timestamp, **kwargs)

    class ViewDistance(DistanceHypothesiser):
        def hypothesise(self, track, detections, timestamp, **kwargs):
            seen[track] = in_view(self.predictor.predict(track, timestamp=timestamp))
            return super().hypothesise(track, detections, timestamp, **kwargs)

    gate = float(chi2.ppf(settings.gate_probability, 2))
    counts: dict = {}  # track -> [hits, scans, misses]
    M, N = settings.confirm

    class RuleDeleter(Deleter):
        """The project's deletion rules, counted per scan."""

        holding: bool = Property(default=False)

        def check_for_deletion(self, track, **kwargs):
            c = counts.setdefault(track, [1, 1, 0])
            inside = seen.pop(track, False)
            met = isinstance(track.state, Update)
            c[0] += self.holding and inside and met
            c[1] += self.holding and inside
            c[2] = 0 if met else c[2] + inside
            spread = np.sqrt(track.covar[0, 0] + track.covar[2, 2]) > settings.delete_std
            if self.holding:
                return spread or c[0] + (N - c[1]) < M
            return spread or c[2] >= settings.delete_misses

    prior = GaussianState(np.zeros((4, 1)), np.diag([1e8, settings.birth_velocity_std**2] * 2))
    distance = ViewDistance(predictor, updater, Mahalanobis(), missed_distance=np.sqrt(gate))
    initiator = MultiMeasurementInitiator(
        prior_state=prior,
        deleter=RuleDeleter(holding=True),
        data_associator=GNNWith2DAssignment(distance),
        updater=updater,
        min_points=M,
    )
    detector = []
    for k in range(sc.steps):
        for i in range(sc.n_uavs):
            t = EPOCH + dt.timedelta(seconds=k * sc.dt) + i * TICK
            z, R, _ = scanned[k][i]
            found = {
                Detection(
                    z[j].reshape(2, 1), timestamp=t,
                    measurement_model=LinearGaussian(4, (0, 2), R[j]),
                    metadata={"uav": i, "step": k},
                )
                for j in range(len(z))
            }  # fmt: skip
            detector.append((t, found, trace.uavs[k, i]))
    feed = []

    def detections():
        for t, found, pose in detector:
            view["uav"] = pose
            feed.append(t)
            yield t, found

    if association == "jpda":
        hyp = ViewPDA(
            predictor, updater, density, prob_detect=sensor.detection_probability,
            prob_gate=settings.gate_probability,
        )  # fmt: skip
        tracker = MultiTargetMixtureTracker(
            initiator=initiator, deleter=RuleDeleter(), detector=detections(),
            data_associator=JPDA(hyp), updater=updater,
        )  # fmt: skip
    else:
        tracker = MultiTargetTracker(
            initiator=initiator, deleter=RuleDeleter(), detector=detections(),
            data_associator=GNNWith2DAssignment(distance), updater=updater,
        )  # fmt: skip
    state = simulation.initial_state(sc, [seed])[0]
    for j in range(sc.n_targets if sc.tracker.briefing else 0):  # the briefing, if any
        m, P = state.mean[0, 0, j], state.cov[0, 0, j]
        tracker._tracks.add(
            Track([GaussianState(m[ORDER_SS].reshape(4, 1), P[np.ix_(ORDER_SS, ORDER_SS)], EPOCH)])
        )
    out = []
    start = time.process_time()
    for n, (_, tracks) in enumerate(tracker, start=1):
        if n % sc.n_uavs == 0:
            means = np.array([tr.state_vector[ORDER_SS, 0] for tr in tracks]).reshape(-1, 4)
            out.append((means, np.array([id(tr) for tr in tracks]), np.ones(len(tracks), bool)))
    cpu = time.process_time() - start
    return out, cpu


# ------------------------------------------------------------------ scores


def score(per_step: list, truth: np.ndarray) -> dict[str, float]:
    """GOSPA and its parts per step, duplicates and never-on-target tracks per target-step."""
    T, Nt = truth.shape[:2]
    gospa = np.zeros((T, 4))
    duplicates = 0
    ever: dict[int, bool] = {}
    held: list[np.ndarray] = []
    for k, (mean, label, confirmed) in enumerate(per_step):
        X = truth[k, :, :2][None]
        Y = mean[:, :2] if len(mean) else np.zeros((1, 2))
        conf = confirmed if len(mean) else np.zeros(1, bool)
        label = label if len(mean) else np.full(1, -1)
        _, g = gospa_assignment(X, np.ones((1, Nt), bool), Y[None], conf[None], CUTOFF, ORDER)
        gospa[k] = (g.distance[0], g.localisation[0], g.missed[0], g.false[0])
        d = np.linalg.norm(Y[:, None, :] - X[0][None, :, :], axis=-1)  # (n, Nt)
        near = np.where(d.min(axis=1) < CUTOFF, d.argmin(axis=1), -1)
        near = np.where(conf, near, -1)
        counts = np.bincount(near[near >= 0], minlength=Nt)
        duplicates += np.maximum(counts - 1, 0).sum()
        for lab, j, c in zip(label, near, conf, strict=True):
            if c:
                ever[int(lab)] = ever.get(int(lab), False) or j >= 0
        held.append(label[conf])
    never = sum(sum(not ever[int(lab)] for lab in labels) for labels in held)
    g = gospa.mean(axis=0)
    return {
        "gospa": g[0], "localisation": g[1], "missed": g[2], "false": g[3],
        "duplicates": duplicates / (T * Nt), "never_on_target": never / (T * Nt),
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description="uavtrack's central tracker against Stone Soup's on a centralized run's "
        "scans, scored alike (see the script's docstring).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--trials", type=int, default=4, help="trials (seeds 0, 1, ...)")
    parser.add_argument("--steps", type=int, default=500, help="steps of each trial")
    parser.add_argument(
        "--association", choices=("gnn", "jpda"), default="jpda", help="both trackers'"
    )
    parser.add_argument("--clutter", type=float, default=2.0, help="false measurements per scan")
    parser.add_argument("--detection", type=float, default=0.9, help="detection probability")
    parser.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE",
        help="another scenario setting, as uavtrack run --set takes it (repeatable)",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=None, help="also write the figures as JSON")
    args = parser.parse_args(argv)
    if min(args.trials, args.steps) < 1:
        parser.error("--trials and --steps must be at least 1")
    if not 0 < args.detection <= 1 or args.clutter < 0:
        parser.error("--detection must be in (0, 1] and --clutter at least 0")
    try:
        sc = scenario(args)
        if args.out is not None:
            _files.check_output(args.out, "--out", force=True)
    except (ScenarioError, UsageError) as exc:
        parser.error(str(exc))
    try:
        run(args, sc)
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        raise SystemExit(130) from None


def run(args: argparse.Namespace, sc: uavtrack.Scenario) -> None:
    """The trials, the table and (with --out) the JSON."""
    rows: dict[str, list[dict]] = {"uavtrack": [], "stonesoup": []}
    for t in range(args.trials):
        seed = uavtrack.trial_seed(0, t)
        trace = uavtrack.run(sc, "centralized", [seed], trace=True).traces[0]
        scanned = scans(sc, trace)
        ours, cpu_ours = replay_uavtrack(sc, seed, trace, scanned)
        theirs, cpu_theirs = stonesoup_tracker(sc, seed, trace, scanned, args.association)
        per_scan = sc.steps * sc.n_uavs
        rows["uavtrack"].append(score(ours, trace.targets) | {"cpu_ms": 1e3 * cpu_ours / per_scan})
        rows["stonesoup"].append(
            score(theirs, trace.targets) | {"cpu_ms": 1e3 * cpu_theirs / per_scan}
        )
        print(
            f"trial {t}: GOSPA uavtrack {rows['uavtrack'][-1]['gospa']:.2f}, "
            f"Stone Soup {rows['stonesoup'][-1]['gospa']:.2f}",
            flush=True,
        )
    names = ("gospa", "localisation", "missed", "false", "duplicates", "never_on_target", "cpu_ms")
    print(
        f"\n{args.association}, P_D {args.detection}, clutter {args.clutter}, "
        f"{args.trials} trial(s) x {args.steps} steps (centralized scans)"
    )
    print("| tracker | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 1) + "|")
    means = {}
    for who, got in rows.items():
        means[who] = {n: statistics.fmean(r[n] for r in got) for n in names}
        print(f"| {who} | " + " | ".join(f"{means[who][n]:.3f}" for n in names) + " |")
    if args.out is not None:
        out = {
            "machine": {"python": platform.python_version(), "processor": platform.machine()},
            "uavtrack": uavtrack.__version__,
            "settings": vars(args) | {"out": str(args.out)},
            "trials": rows,
            "means": means,
        }
        _files.write_text(args.out, json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
