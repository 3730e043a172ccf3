"""The records of the decision cycle: what persists between cycles (`State`), what a
cycle decided before it flies (`Pending`), what it recorded (`Cycle`, stacked over the
steps as a `Trace`), and what a run gives (`Result`, `BatchResult`).

They sit below the metrics and the driver (`simulation`), so that the metrics, the track
scoring, the agents and the outputs name them without naming the driver. Every field a
cycle records is declared once, in `Cycle`: the trace, the recorder and the metrics are
derived from it.
"""

# Strict typing, less the unknown-type rules (numpy resolves an overloaded call with an
# argument of type Any, as any array's shape, to Unknown).
# pyright: reportUnknownMemberType=false, reportUnknownArgumentType=false
# pyright: reportUnknownVariableType=false

from __future__ import annotations

from dataclasses import dataclass, field, fields, make_dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import estimation, flight
from .airspace import avoidance
from .config import Scenario
from .faults import PROTOCOLS
from .methods.base import Assigned, Fused, FusedTracks, Held
from .radio import Radio, RadioState
from .tracks import manage
from .tracks import scan as scans

__all__ = [
    "RECORDED",
    "RESULT_METRICS",
    "TRACKED",
    "BatchResult",
    "Cycle",
    "Pending",
    "Result",
    "State",
    "Trace",
]


@dataclass(frozen=True, kw_only=True)
class State:
    """What persists between cycles, for B trials, all at step k.

    uavs: (B, Nu, 5) true UAV states; mean (B, Nu, Nt, 4) and cov (B, Nu, Nt, 4, 4):
    each UAV's beliefs predicted to k (the prior at k = 0); alive (B, Nu); target (B,
    Nu) each UAV's last target (-1: none yet); radio: messages in flight and link
    states; held: the bids each UAV holds of the others (only when messages get lost);
    flight: the autopilot that flies the UAVs (`flight`; None: the paper's unicycle). An
    aircraft has more state than `uavs` and flying it moves it on: a State is stepped once.
    modes: the IMM's mode-conditioned beliefs (`estimation.Modes`; None: the paper's
    filter), of which mean and cov are the combined estimate. seen (B, Nu, Nt): the
    step each UAV last measured each target (-1: never; kept with ``robust.gate``).
    With unknown association (``tracker.association`` gnn or jpda) mean and cov are
    each UAV's K track slots (B, Nu, K, ...), book their labels, statuses and counters
    (`tracks.manage.Book`), target the label each UAV followed last, and central a
    central node's tracks (centralized).
    """

    k: int
    uavs: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    alive: np.ndarray
    target: np.ndarray
    radio: RadioState = RadioState()
    held: Held | None = None
    flight: flight.Autopilot | None = None
    modes: estimation.Modes | None = None
    seen: np.ndarray | None = None
    book: manage.Book | None = None
    central: manage.Slots | None = None
    labels: np.ndarray | None = None  # (B, L) the labels of the held bids' columns
    tombs: np.ndarray | None = None  # (B, Nu, T, 2) the tombstones each UAV knows
    beacons: avoidance.Heard | None = None  # with planner.avoidance: the states heard
    recent: np.ndarray | None = None  # (B, Nu) and the measured model: the recent commands
    told: np.ndarray | None = None  # with fusion.trigger: the confidence each UAV last sent
    told_labels: np.ndarray | None = None  # and with tracks the label of each slot it sent


def _record(shape: str, doc: str, dtype: type = np.float64):
    return field(metadata={"shape": shape, "doc": doc, "dtype": dtype})


@dataclass(frozen=True, kw_only=True)
class Cycle:
    """What one cycle decided and measured, for B trials: each field is (B, *shape).

    The trace holds the same fields over the steps (T, *shape); this class is the one
    place a recorded quantity is declared.
    """

    uavs: np.ndarray = _record(
        "(Nu, 5)",
        "true UAV states x, y, h, V, heading [m, m, m, m/s, rad] when deciding (with "
        "uav.dynamics = jsbsim: V the ground speed, heading the course over ground)",
    )
    observed: np.ndarray = _record(
        "(Nu, Nt)", "target inside the UAV's observation disk (a failed UAV sees nothing)", bool
    )
    mean: np.ndarray = _record(
        "(Nu, K, 4)",
        "each UAV's fused estimate of each target, K = Nt (NaN: the UAV has failed); with "
        "tracker.association gnn or jpda, of each of its K track slots (see label, status)",
    )
    cov: np.ndarray = _record("(Nu, K, 4, 4)", "its covariance")
    bids: np.ndarray = _record(
        "(Nu, K)",
        "the UAV's best planning value per target (per confirmed track), its bid (NaN: the "
        "UAV failed, a slot not confirmed, or a bid not scored because no assignment can "
        "read it, see planner.prune)",
    )
    assignment: np.ndarray = _record(
        "(Nu,)",
        "the target each UAV tracks, or with tracker.association gnn or jpda the team "
        "label of its track (-1: the UAV has failed, or follows no track)",
        np.int64,
    )
    action: np.ndarray = _record(
        "(Nu,)", "the bank angle flown [rad] (with uav.dynamics = jsbsim, the autopilot's setpoint)"
    )
    rounds: np.ndarray = _record(
        "(Nu,)", "consensus rounds the UAV ran (D_i, plus robust.extra_rounds)", np.int64
    )
    messages: np.ndarray = _record(
        "()",
        "radio messages sent, all protocols (see the documentation, Performance: messages)",
        np.int64,
    )
    delivered: np.ndarray = _record("()", "radio messages that arrived", np.int64)
    late: np.ndarray = _record(
        f"({len(PROTOCOLS)},)",
        "radio messages the fault model delivers that had not arrived when their receiver "
        "stopped waiting, by protocol (" + ", ".join(PROTOCOLS) + "): late, or never sent "
        "(their sender stopped or gone); always 0 in the simulator, whose radio is on time",
        np.int64,
    )
    bytes: np.ndarray = _record(
        "(Nu,)",
        "radio bytes each UAV sent (see the trace format, Bytes): its frames as the agent "
        "form puts them on the wire",
        np.int64,
    )
    node_bytes: np.ndarray = _record("()", "radio bytes the central node sent", np.int64)
    conflicts: np.ndarray = _record(
        "()", "targets followed by two or more UAVs while another has none", np.int64
    )
    alive: np.ndarray = _record("(Nu,)", "the UAV has not failed", bool)
    decision_time_ms: np.ndarray = _record(
        "(Nu,)", "planning and assignment per UAV [ms of CPU time] (NaN inside a batch)"
    )
    decision_wall_ms: np.ndarray = _record(
        "(Nu,)", "the same in wall time [ms] (NaN inside a batch)"
    )
    label: np.ndarray | None = field(default=None, repr=False, compare=False)
    """With unknown association: each slot's team label (Nu, K) (-1: empty)."""
    status: np.ndarray | None = field(default=None, repr=False, compare=False)
    """With unknown association: each slot's status (Nu, K) (`tracks.manage`)."""
    existence: np.ndarray | None = field(default=None, repr=False, compare=False)
    """With unknown association: each slot's probability of existence (Nu, K)."""
    scan: scans.Scan | None = field(default=None, repr=False, compare=False)
    """With unknown association: each UAV's scan."""
    confidence: np.ndarray | None = field(default=None, repr=False, compare=False)
    """1 / trace(cov) (Nu, Nt) when the method already has it (not recorded: the
    metrics read it instead of computing it again)."""


RECORDED = tuple(f for f in fields(Cycle) if "shape" in f.metadata)
"""The fields of `Cycle` a trace holds."""

TRACKED: dict[str, tuple[str, str, type]] = {
    "label": ("(Nu, K)", "team label of each track slot (-1: empty)", np.int64),
    "status": ("(Nu, K)", "its status: 0 empty, 1 tentative, 2 confirmed", np.int8),
    "existence": (
        "(Nu, K)",
        "its probability of existence (0: an empty slot; with tracker.confirmation = m_of_n "
        "carried but not what confirms it)",
        np.float64,
    ),
    "scan_polar": (
        "(Nu, Z, 2)",
        "each UAV's measurements of the scan, range [m] and bearing [rad], in the order the "
        "UAV received them (Z: the most of any UAV and step; padding 0)",
        np.float64,
    ),
    "scan_z": ("(Nu, Z, 2)", "their conversion to a ground position [m]", np.float64),
    "scan_valid": ("(Nu, Z)", "a measurement, not padding", bool),
    "scan_origin": (
        "(Nu, Z)",
        "for evaluation only: the target measured, -1 clutter, -2 padding",
        np.int64,
    ),
}
"""What a trace holds beside `RECORDED` with tracker.association gnn or jpda: name ->
(shape per step, meaning, dtype)."""


def _trace_arrays(self: DataclassInstance) -> dict[str, np.ndarray]:
    out = {f.name: getattr(self, f.name) for f in fields(self)}
    return {name: value for name, value in out.items() if value is not None}


if TYPE_CHECKING:  # what a checker knows of Trace, whose fields are made from Cycle's
    from _typeshed import DataclassInstance

    class Trace:
        def __init__(self, targets: np.ndarray, **recorded: np.ndarray | None) -> None: ...
        def __getattr__(self, name: str) -> np.ndarray: ...
        def arrays(self) -> dict[str, np.ndarray]: ...

else:
    Trace = make_dataclass(
        "Trace",
        [("targets", np.ndarray)]
        + [(f.name, np.ndarray) for f in RECORDED]
        + [(name, np.ndarray | None, field(default=None)) for name in TRACKED],
        frozen=True,
        namespace={
            "arrays": _trace_arrays,
            "__doc__": "Everything a run did, step by step: targets (T, Nt, 4) the true target "
            "states x, y, vx, vy at each cycle, then every field of `Cycle` over the T steps, "
            "and with tracker.association gnn or jpda those of `TRACKED` (None otherwise). "
            "arrays() gives them as a dict (the .npz of `uavtrack run --trace`).",
            "__module__": __name__,
        },
    )


@dataclass(frozen=True, kw_only=True)
class Pending:
    """A cycle up to its decision: what every UAV knows after sensing, filtering and
    fusion, its bids, the method's assignment and the action it would fly. `finish`
    flies the method's actions or others (an environment's agents)."""

    k: int
    uavs: np.ndarray
    believed: np.ndarray
    alive: np.ndarray
    observed: np.ndarray
    radio: Radio
    fused: Fused
    bids: np.ndarray
    assigned: Assigned
    own: np.ndarray  # (B, Nu) the method's actions, indices into the action set
    plan_seconds: np.ndarray  # (2,): CPU, wall (`timing`)
    belief: estimation.Belief  # each UAV's own (mean, cov, modes) after its update, before fusion
    detected: np.ndarray  # (B, Nu, Nt) the pairs measured (missed targets not)
    tracks: FusedTracks | None = None  # with unknown association: the tracks after fusion
    scan: scans.Scan | None = None  # with unknown association: the scans
    columns: np.ndarray | None = None  # with unknown association: the held label each took
    labels: np.ndarray | None = None  # (B, L) with unknown association: the columns' labels
    held: np.ndarray | None = None  # (B,) with unknown association: labels held confirmed
    # with a method that does not plan: this cycle's beacons, got (B, Nu, Nu) [receiver,
    # sender] those that arrived and states (B, Nu, 5) as their senders sent them
    beacons: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def width(self) -> int:
        """What a conflict is counted over: the targets, or with unknown association the
        labels the living UAVs hold confirmed (`columns` indexes them; `held` per trial)."""
        return self.bids.shape[-1] if self.held is None else int(self.held.max(initial=1))


Summary = str | int | float | list[float] | None
"""A value of `Result.summary`: the method, the seed, a metric, or per-target rates."""


@dataclass(frozen=True)
class BatchResult:
    """Per-trial metrics of a batch (see `metrics.METRICS`) and optional traces."""

    method: str
    scenario: Scenario
    metrics: dict[str, np.ndarray]
    traces: list[Trace] | None = field(default=None, repr=False)


@dataclass(frozen=True, kw_only=True)
class Result:
    """One trial: the paper's metric, the estimation quality, costs, and the trace.

    The metrics are those of `metrics.METRICS` (units and meaning there):
    observation_rate (Sec. 7); per_target (Nt,); rmse and nees over every UAV's fused
    estimate; rmse_best and nees_best of the team's best estimate; nees_median,
    nees_inside and their _best twins: the median of the same NEES samples and the
    fraction inside the 95 % chi-square(4) interval; rounds: mean D_i per
    UAV and step; messages and delivered per step; bytes per UAV and step; conflicts
    per step; failed: UAVs failed by the end; separation_losses, separation_min and
    conflict_time (`airspace.separation`); decision_time_ms (CPU) and decision_wall_ms
    per UAV and cycle.
    """

    method: str
    seed: int | None
    scenario: Scenario
    observation_rate: float
    per_target: np.ndarray
    in_view_std: float
    rmse: float
    rmse_best: float
    nees: float
    nees_median: float
    nees_inside: float
    nees_best: float
    nees_best_median: float
    nees_best_inside: float
    ospa: float
    ospa_best: float
    gospa: float
    gospa_best: float
    gospa_missed_best: float
    gospa_localisation: float
    gospa_missed: float
    gospa_false: float
    switches: float
    fragmentations: float
    unassigned_tracks: float
    unassigned_tracks_per_target: float
    duplicate_tracks: float
    stale_tracks: float
    never_tracks: float
    never_tracks_new: float
    gospa_team: float
    label_purity: float
    ospa2: float
    ospa2_team: float
    time_to_confirm: float
    time_to_confirm_team: float
    never_confirmed: float
    siap_completeness: float
    siap_ambiguity: float
    siap_spuriousness: float
    rounds: float
    messages: float
    delivered: float
    bytes: float
    conflicts: float
    failed: float
    separation_losses: float
    separation_min: float
    conflict_time: float
    decision_time_ms: float
    decision_wall_ms: float
    trace: Trace | None = field(default=None, repr=False)

    def summary(self) -> dict[str, Summary]:
        """JSON-ready metrics (the names of `metrics.METRICS`, in its order: the fields
        after the scenario, a test holds them equal)."""
        out: dict[str, Summary] = {"method": self.method, "seed": self.seed}
        for name in RESULT_METRICS:
            value = getattr(self, name)
            out[name] = [float(x) for x in value] if name == "per_target" else float(value)
        return out


RESULT_METRICS = tuple(
    f.name for f in fields(Result) if f.name not in ("method", "seed", "scenario", "trace")
)
"""The metrics a `Result` holds, in the order of `metrics.METRICS`."""
