"""Multi-camera people tracker of the master node (pure core, no ROS).

People are tracked on the world ground plane with one constant-velocity Kalman filter per person
(:mod:`face_reid_master.tracking.kalman`), global-nearest-neighbour association
(``scipy.optimize.linear_sum_assignment``) on the Mahalanobis distance gated at the chi-square
quantile, and a TENTATIVE -> CONFIRMED -> LOST -> DELETED lifecycle, as in OpenPTrack (Koide et
al. 2017, Sec. III-A).  A person who leaves every view gets a new track id on return; restoring the
identity is the face table's job.

Association, per camera frame (see ``Tracker._associate``): tracks are served in a cascade (fresh
confirmed, coasting confirmed, lost, tentative); within a group, GNN on ``d2 + log det S`` inside
the ``gate_probability`` chi-square gate, then a second pass for the leftovers (wider gate, or
within ``min_person_separation_m`` of the prediction, or within reach of the last detection) that
keeps people who turn or stop.  Leftover detections start TENTATIVE tracks unless they are within
``min_person_separation_m`` of a track; a tentative track that comes that close to a confirmed one is
a duplicate and is deleted.  These rules were needed for one-track-per-person on the synthetic
scenarios of ``test/trajectories.py`` (noise up to 0.15 m, misses, turns; see the tests).

Time and out-of-order frames
----------------------------
The tracker clock is the newest *accepted* frame stamp (data-driven: no wall clock).  Each camera
frame is applied at once (no added latency).  A frame older than the clock but within
``max_detection_delay_s`` is applied *exactly*: every track keeps a short history of its
measurements and posteriors; the late frame is gated against each track's state predicted (forward)
from its last posterior at or before the frame stamp, and a matched track inserts the measurement in
stamp order and re-runs its filter over the few later measurements.  The resulting track state is
identical to processing that track's measurements in stamp order.  Decisions already reported
(earlier associations, created/deleted ids) are never revised.  The single approximation: a late
detection is gated against a track *born after* it by predicting that track's first state backwards.
Older frames, and frames more than ``max_future_stamp_s`` ahead of the clock, are rejected and
counted; ``clock_resync_frames`` consecutive rejections in the same direction are taken as a clock
jump (cameras restarted after an idle period, or a bag replay looping back) and the clock follows.
"""

from __future__ import annotations

import bisect
import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from face_reid_master.tracking.kalman import ConstantVelocityModel, mahalanobis_sq

__all__ = [
    "Detection",
    "FrameStatus",
    "TrackSnapshot",
    "TrackState",
    "Tracker",
    "TrackerConfig",
    "TrackerStats",
    "UpdateResult",
]

FloatArray = NDArray[np.float64]

_EPS_S = 1e-9  # tolerance on time comparisons, so that "exactly lost_after_s later" counts
_PRUNE_MARGIN_S = 1e-6  # history kept slightly beyond max_detection_delay_s (see _prune)


class TrackState(enum.IntEnum):
    """Lifecycle state of a track."""

    TENTATIVE = 0
    CONFIRMED = 1
    LOST = 2
    DELETED = 3


_TENTATIVE = int(TrackState.TENTATIVE)
_CONFIRMED = int(TrackState.CONFIRMED)
_LOST = int(TrackState.LOST)


class FrameStatus(enum.Enum):
    """What the tracker did with one camera frame (or :meth:`Tracker.advance` call)."""

    APPLIED = "applied"  # in stamp order
    APPLIED_LATE = "applied_late"  # older than the clock, within max_detection_delay_s
    REJECTED_LATE = "rejected_late"
    REJECTED_FUTURE = "rejected_future"
    ADVANCED = "advanced"  # clock moved by advance(), no detections


def _check_real(name: str, value: object, *, positive: bool = True, allow_zero: bool = False) -> float:
    if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
        raise ValueError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and (v < 0.0 or (v == 0.0 and not allow_zero)):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")
    return v


def _check_int(name: str, value: object, minimum: int) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
        raise ValueError(f"{name} must be an int, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker parameters (metres, seconds).  Validated on construction; ValueError on bad values.

    ``accel_noise_mps2``: white-acceleration noise std over 1 s (spectral density = its square).
    ``init_velocity_std_mps``: velocity prior std of a new track.
    ``gate_probability``: detections outside the chi-square(2 dof) quantile of a track are not
    associated with it.
    ``detections_to_confirm`` hits within ``confirm_window_s`` of creation confirm a track; a
    tentative track not confirmed by then is deleted.
    ``lost_after_s``: a confirmed track without detection for this long becomes LOST; after
    ``delete_after_s`` more it is DELETED.
    ``max_detection_delay_s``: frames up to this much older than the newest accepted stamp are applied
    (exactly, see module doc); older ones are rejected.
    ``max_future_stamp_s``: frames further than this ahead of the newest stamp are rejected...
    ``clock_resync_frames``: ...unless this many consecutive frames are rejected in the same
    direction, which is taken as a clock jump (0 disables).
    ``max_gate_distance_m``: additional Euclidean gate around the predicted position (and cap of the
    second-pass reach), so that a coasting or LOST track, whose covariance grows to metres, cannot
    capture someone else (inf = off).  In a crowd people are hidden behind each other all the time:
    on simulated 20-person scenes ~80 % of the detections such tracks took more than 1 m from their
    prediction were another person's (~40 % at 0.5-1 m), hence 1 m; a hidden person who reappears
    further off gets a new track, whose identity the face table restores.
    ``min_person_separation_m``: two people are assumed never closer than this.  A detection that
    fails every gate but lies this close to the predicted position of an unmatched track, or within
    ``min_person_separation_m + max_speed_mps * (time since its last detection)`` of that last
    detection, is associated with it in a second pass (turns and stops outrun the constant-velocity
    gate).  A leftover detection this close to any track or to another new detection starts no
    track (with a 99 % gate ~1 % of a person's detections miss their own track's gate; each would
    otherwise spawn a duplicate), and a tentative track this close to a confirmed one is deleted.
    ``coast_after_s``: a confirmed track not detected for this long is "coasting": it is offered
    detections only after the freshly detected tracks have had both association passes.
    ``camera_window_s``: a track's ``cameras`` are those that detected it within this window.
    ``max_tracks``: cap on live tracks (bounded latency under clutter); extra detections are dropped.
    """

    accel_noise_mps2: float = 1.0
    init_velocity_std_mps: float = 1.0
    gate_probability: float = 0.99
    detections_to_confirm: int = 3
    confirm_window_s: float = 1.0
    lost_after_s: float = 1.0
    delete_after_s: float = 3.0
    max_detection_delay_s: float = 0.3
    max_future_stamp_s: float = 2.0
    clock_resync_frames: int = 5
    max_gate_distance_m: float = 1.0
    min_person_separation_m: float = 0.4
    max_speed_mps: float = 2.0
    coast_after_s: float = 0.25
    camera_window_s: float = 0.5
    max_tracks: int = 200

    def __post_init__(self) -> None:
        for name in ("accel_noise_mps2", "init_velocity_std_mps", "confirm_window_s", "lost_after_s"):
            _check_real(name, getattr(self, name))
        for name in (
            "delete_after_s",
            "max_detection_delay_s",
            "max_future_stamp_s",
            "camera_window_s",
            "min_person_separation_m",
            "max_speed_mps",
            "coast_after_s",
        ):
            _check_real(name, getattr(self, name), allow_zero=True)
        p = _check_real("gate_probability", self.gate_probability)
        if not 0.0 < p < 1.0:
            raise ValueError(f"gate_probability must be in (0, 1), got {self.gate_probability!r}")
        gate_m = self.max_gate_distance_m
        if not isinstance(gate_m, (int, float)) or isinstance(gate_m, bool) or not gate_m > 0:
            raise ValueError(f"max_gate_distance_m must be a number > 0 (inf allowed), got {gate_m!r}")
        _check_int("detections_to_confirm", self.detections_to_confirm, 1)
        _check_int("clock_resync_frames", self.clock_resync_frames, 0)
        _check_int("max_tracks", self.max_tracks, 1)

    @property
    def gate_mahalanobis_sq(self) -> float:
        """Squared-Mahalanobis gate: chi-square quantile at ``gate_probability`` with 2 dof."""
        return float(chi2.ppf(self.gate_probability, df=2))

    @property
    def motion_model(self) -> ConstantVelocityModel:
        return ConstantVelocityModel(self.accel_noise_mps2, self.init_velocity_std_mps)


@dataclass(frozen=True)
class Detection:
    """One person detection of one camera frame, already in the world frame.

    ``position_xy``: (2,) ground-plane position in metres (non-finite values are accepted here and
    rejected/counted by the tracker, since they come from sensors).  ``position_std_m``: isotropic
    measurement std (a non-finite or non-positive value is likewise rejected by the tracker).
    ``height_m``: head/top height above the floor (nan if unknown).  ``embedding``: 1-D face
    feature (128-d OpenFace) or None.  ``payload_index``: free index back into the source message.
    """

    position_xy: FloatArray
    camera_id: str
    position_std_m: float = 0.1
    height_m: float = float("nan")
    embedding: NDArray[np.floating] | None = None
    face_score: float = 0.0
    payload_index: int = -1

    def __post_init__(self) -> None:
        pos = np.array(self.position_xy, dtype=np.float64)
        if pos.shape != (2,):
            raise ValueError(f"position_xy must have shape (2,), got {pos.shape}")
        pos.flags.writeable = False
        object.__setattr__(self, "position_xy", pos)
        if not isinstance(self.camera_id, str) or not self.camera_id:
            raise ValueError(f"camera_id must be a non-empty str, got {self.camera_id!r}")
        for name in ("position_std_m", "height_m", "face_score"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
                raise ValueError(f"{name} must be a real number, got {type(value).__name__}")
            object.__setattr__(self, name, float(value))
        if self.embedding is not None:
            emb = np.asarray(self.embedding)
            if emb.ndim != 1 or emb.size == 0 or not np.issubdtype(emb.dtype, np.floating):
                raise ValueError(
                    f"embedding must be a non-empty 1-D float array or None, got {emb.dtype} {emb.shape}"
                )
            object.__setattr__(self, "embedding", emb)
        _check_int("payload_index", self.payload_index, -1)


@dataclass(frozen=True)
class TrackSnapshot:
    """Read-only view of one track at ``stamp_s`` (state predicted to that time).

    ``covariance`` is the 4x4 covariance of (x, y, vx, vy).  ``cameras``: cameras that detected it
    within ``camera_window_s`` of the clock.  ``associated``: (detection index, embedding) pairs
    associated with it by the most recent ``update`` call (empty if it was not detected then).
    """

    track_id: int
    state: TrackState
    position_xy: FloatArray
    velocity_xy: FloatArray
    covariance: FloatArray
    stamp_s: float
    created_s: float
    last_seen_s: float
    hits: int
    cameras: frozenset[str]
    height_m: float
    associated: tuple[tuple[int, NDArray[np.floating] | None], ...]

    @property
    def position_covariance(self) -> FloatArray:
        return self.covariance[:2, :2]


@dataclass(frozen=True)
class UpdateResult:
    """What one ``update``/``advance`` call did.

    ``associations``: (track_id, detection index in the input sequence) pairs, including the
    detections that created new tracks.  ``created`` / ``confirmed`` / ``lost`` / ``recovered`` /
    ``deleted``: track ids that changed state in this call.  ``rejected_detections``: input indices
    rejected (non-finite position, bad std, track limit).  ``suppressed_detections``: valid but
    unassociated detections that started no track because they lie within ``min_person_separation_m``
    of a track (whose person was already matched: a duplicate detection).  ``clock_resync``: this frame
    re-based the clock after a run of rejected frames (on a backward jump all tracks are deleted first).
    """

    stamp_s: float
    camera_id: str
    status: FrameStatus
    associations: tuple[tuple[int, int], ...] = ()
    created: tuple[int, ...] = ()
    confirmed: tuple[int, ...] = ()
    lost: tuple[int, ...] = ()
    recovered: tuple[int, ...] = ()
    deleted: tuple[int, ...] = ()
    rejected_detections: tuple[int, ...] = ()
    suppressed_detections: tuple[int, ...] = ()
    clock_resync: bool = False

    @property
    def accepted(self) -> bool:
        return self.status in (FrameStatus.APPLIED, FrameStatus.APPLIED_LATE)

    def track_of_detection(self) -> dict[int, int]:
        """Detection index -> track id for this frame."""
        return {det: tid for tid, det in self.associations}


@dataclass
class TrackerStats:
    """Counters since construction (``Tracker.stats`` returns a copy)."""

    frames_processed: int = 0
    frames_out_of_order: int = 0  # processed although older than the clock (within the bound)
    frames_rejected_late: int = 0
    frames_rejected_future: int = 0
    clock_resyncs: int = 0
    detections_received: int = 0
    detections_associated: int = 0
    detections_rejected_nonfinite: int = 0
    detections_rejected_bad_std: int = 0
    detections_dropped_track_limit: int = 0
    detections_suppressed_near_track: int = 0
    tracks_merged: int = 0  # tentative duplicates dropped next to a confirmed track (also in deleted)
    tracks_created: int = 0
    tracks_confirmed: int = 0
    tracks_deleted: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _gnn(cost: FloatArray, feasible: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Global-nearest-neighbour assignment restricted to ``feasible`` pairs.

    Infeasible pairs cost more than any set of feasible ones, so the result has the maximum number
    of feasible matches and, among those, the minimum total cost (OpenPTrack-style GNN).
    """
    rows_ok = np.flatnonzero(feasible.any(axis=1))
    if rows_ok.shape[0] == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    cols_ok = np.flatnonzero(feasible.any(axis=0))
    sub = cost[np.ix_(rows_ok, cols_ok)]
    sub_feasible = feasible[np.ix_(rows_ok, cols_ok)]
    lo, hi = sub[sub_feasible].min(), sub[sub_feasible].max()
    big = (hi - lo) * (min(sub.shape) + 1.0) + 1.0
    r, c = linear_sum_assignment(np.where(sub_feasible, sub - lo, big))
    keep = sub_feasible[r, c]
    return rows_ok[r[keep]], cols_ok[c[keep]]


# One filter step of a track's history: (stamp, z (2,), r2, x_post (4,), P_post (4, 4)).
_Entry = tuple[float, FloatArray, float, FloatArray, FloatArray]


@dataclass(slots=True)
class _Aux:
    """Per-track Python-side data (the numeric state lives in the Tracker's stacked arrays)."""

    history: list[_Entry]
    stamps: list[float]
    cameras: dict[str, float] = field(default_factory=dict)
    height_m: float = float("nan")
    height_stamp_s: float = -math.inf


class Tracker:
    """Multi-camera GNN + Kalman people tracker on the world ground plane.

    Call :meth:`update` once per camera frame (any order within ``max_detection_delay_s``), read
    :meth:`snapshots` to publish.  Not thread-safe.
    """

    def __init__(self, config: TrackerConfig | None = None) -> None:
        if config is None:
            config = TrackerConfig()
        if not isinstance(config, TrackerConfig):
            raise ValueError(f"config must be a TrackerConfig, got {type(config).__name__}")
        self._cfg = config
        self._model = config.motion_model
        self._gate = config.gate_mahalanobis_sq
        self._stats = TrackerStats()
        self._next_id = 1
        self._clock: float | None = None
        self._reject_run = 0
        self._reject_dir = 0  # +1 future, -1 late
        self._last_assoc: dict[int, list[tuple[int, NDArray[np.floating] | None]]] = {}
        self._clear_arrays()

    def _clear_arrays(self) -> None:
        self._ids = np.zeros(0, dtype=np.int64)
        self._state = np.zeros(0, dtype=np.int8)
        self._created = np.zeros(0)
        self._last_seen = np.zeros(0)
        self._hits = np.zeros(0, dtype=np.int64)
        self._x = np.zeros((0, 4))
        self._P = np.zeros((0, 4, 4))
        self._t = np.zeros(0)  # stamp of each track's newest posterior (= newest measurement)
        self._zmeas = np.zeros((0, 2))  # position of each track's newest measurement
        self._aux: list[_Aux] = []

    # ------------------------------------------------------------------ read-only properties
    @property
    def config(self) -> TrackerConfig:
        return self._cfg

    @property
    def stats(self) -> TrackerStats:
        return replace(self._stats)

    @property
    def clock_s(self) -> float | None:
        """Newest accepted stamp (None before the first frame)."""
        return self._clock

    @property
    def num_tracks(self) -> int:
        return int(self._ids.shape[0])

    def track_ids(self) -> list[int]:
        return [int(i) for i in self._ids]

    # ------------------------------------------------------------------ main entry point
    def update(self, detections: Sequence[Detection], stamp_s: float, camera_id: str) -> UpdateResult:
        """Fuse one camera frame: ``detections`` seen by ``camera_id`` at ``stamp_s`` (seconds).

        Raises ValueError for programming errors (non-finite stamp, wrong types, a detection whose
        camera_id differs from the frame's); bad sensor values are rejected and counted instead.
        """
        stamp = _check_real("stamp_s", stamp_s, positive=False)
        if not isinstance(camera_id, str) or not camera_id:
            raise ValueError(f"camera_id must be a non-empty str, got {camera_id!r}")
        if isinstance(detections, (str, bytes)) or not isinstance(detections, Sequence):
            raise ValueError(f"detections must be a sequence of Detection, got {type(detections).__name__}")
        positions: list[FloatArray] = []
        stds: list[float] = []
        for i, det in enumerate(detections):
            if type(det) is not Detection and not isinstance(det, Detection):
                raise ValueError(f"detections[{i}] must be a Detection, got {type(det).__name__}")
            if det.camera_id != camera_id:
                raise ValueError(
                    f"detections[{i}].camera_id {det.camera_id!r} != frame camera_id {camera_id!r}"
                )
            positions.append(det.position_xy)
            stds.append(det.position_std_m)

        status, resync, deleted_by_reset = self._admit(stamp)
        if status in (FrameStatus.REJECTED_LATE, FrameStatus.REJECTED_FUTURE):
            return UpdateResult(stamp, camera_id, status)
        self._stats.frames_processed += 1
        if status is FrameStatus.APPLIED_LATE:
            self._stats.frames_out_of_order += 1
        self._last_assoc = {}
        expired: tuple[int, ...] = ()
        if self._clock is not None and stamp > self._clock and self._ids.shape[0]:
            # Tracks that timed out by this frame's time must not take its detections.
            expired = self._delete(self._expired(stamp))

        # ---- input detections: reject non-finite positions / bad stds
        m = len(detections)
        self._stats.detections_received += m
        rejected: list[int] = []
        if m:
            z_all = np.array(positions)
            std_all = np.array(stds)
            finite = np.isfinite(z_all).all(axis=1)
            good_std = np.isfinite(std_all) & (std_all > 0.0)
            self._stats.detections_rejected_nonfinite += int((~finite).sum())
            self._stats.detections_rejected_bad_std += int((finite & ~good_std).sum())
            valid = np.flatnonzero(finite & good_std)
            rejected.extend(int(i) for i in np.flatnonzero(~(finite & good_std)))
            z = z_all[valid]
            r2 = std_all[valid] ** 2
        else:
            valid = np.zeros(0, dtype=np.int64)
            z = np.zeros((0, 2))
            r2 = np.zeros(0)

        # ---- associate with live tracks
        associations: list[tuple[int, int]] = []
        unmatched = np.ones(valid.shape[0], dtype=bool)
        near_track = np.zeros(valid.shape[0], dtype=bool)
        if valid.shape[0] and self._ids.shape[0]:
            rows, cols, x_pred, P_pred, late, near_track = self._associate(z, r2, stamp)
            unmatched[cols] = False
            self._apply_matches(rows, cols, x_pred, P_pred, late, z, r2, valid, detections, stamp, camera_id)
            associations.extend((int(self._ids[r]), int(valid[c])) for r, c in zip(rows, cols, strict=True))
            self._stats.detections_associated += int(rows.shape[0])

        # ---- new tracks from unmatched detections not too close to a track or to each other
        created: list[int] = []
        suppressed: list[int] = []
        new_cols = np.zeros(0, dtype=np.intp)
        suppressed_cols = new_cols
        if unmatched.any():
            new_cols = self._new_track_candidates(z, np.flatnonzero(unmatched & ~near_track))
            suppressed_cols = np.setdiff1d(np.flatnonzero(unmatched), new_cols)
        if suppressed_cols.shape[0]:
            self._stats.detections_suppressed_near_track += int(suppressed_cols.shape[0])
            suppressed.extend(int(valid[c]) for c in suppressed_cols)
        if new_cols.shape[0]:
            room = max(0, self._cfg.max_tracks - int(self._ids.shape[0]))
            if new_cols.shape[0] > room:
                dropped = new_cols[room:]
                self._stats.detections_dropped_track_limit += int(dropped.shape[0])
                rejected.extend(int(valid[c]) for c in dropped)
                new_cols = new_cols[:room]
            if new_cols.shape[0]:
                created = self._create(
                    z[new_cols], r2[new_cols], valid[new_cols], detections, stamp, camera_id
                )
                associations.extend((tid, int(valid[c])) for tid, c in zip(created, new_cols, strict=True))

        if self._clock is None or stamp > self._clock:
            self._clock = stamp
        confirmed, lost, recovered, deleted = self._tick()
        return UpdateResult(
            stamp_s=stamp,
            camera_id=camera_id,
            status=status,
            associations=tuple(associations),
            created=tuple(created),
            confirmed=confirmed,
            lost=lost,
            recovered=recovered,
            deleted=deleted_by_reset + expired + deleted,
            rejected_detections=tuple(sorted(rejected)),
            suppressed_detections=tuple(sorted(suppressed)),
            clock_resync=resync,
        )

    def advance(self, stamp_s: float) -> UpdateResult:
        """Move the clock forward to ``stamp_s`` without detections and apply lifecycle timeouts.

        For a node timer when no camera frames arrive; a stamp not newer than the clock is a no-op.
        Note that frames older than ``stamp_s - max_detection_delay_s`` will then be rejected.
        """
        stamp = _check_real("stamp_s", stamp_s, positive=False)
        if self._clock is not None and stamp <= self._clock:
            return UpdateResult(stamp, "", FrameStatus.ADVANCED)
        self._clock = stamp
        self._last_assoc = {}
        confirmed, lost, recovered, deleted = self._tick()
        return UpdateResult(
            stamp,
            "",
            FrameStatus.ADVANCED,
            confirmed=confirmed,
            lost=lost,
            recovered=recovered,
            deleted=deleted,
        )

    def reset(self) -> tuple[int, ...]:
        """Delete every track and forget the clock; returns the deleted ids (ids are never reused)."""
        deleted = tuple(int(i) for i in self._ids)
        self._stats.tracks_deleted += len(deleted)
        self._clear_arrays()
        self._clock = None
        self._reject_run = 0
        self._last_assoc = {}
        return deleted

    def snapshots(self, at_s: float | None = None, include_tentative: bool = True) -> list[TrackSnapshot]:
        """Snapshots of the live tracks, sorted by id, states predicted forward to ``at_s``.

        ``at_s`` defaults to the clock; a track whose newest posterior is later than ``at_s`` is
        reported at its own stamp (never predicted backwards).
        """
        n = self._ids.shape[0]
        if n == 0:
            return []
        at = self._clock if at_s is None else _check_real("at_s", at_s, positive=False)
        assert at is not None
        t_out = np.maximum(self._t, at)
        x, P = self._model.predict(self._x, self._P, t_out - self._t)
        window_start = (self._clock if self._clock is not None else at) - self._cfg.camera_window_s - _EPS_S
        out: list[TrackSnapshot] = []
        for i in range(n):
            state = TrackState(int(self._state[i]))
            if not include_tentative and state is TrackState.TENTATIVE:
                continue
            aux = self._aux[i]
            tid = int(self._ids[i])
            cov = P[i].copy()
            pos = x[i, :2].copy()
            vel = x[i, 2:].copy()
            for arr in (cov, pos, vel):
                arr.flags.writeable = False
            out.append(
                TrackSnapshot(
                    track_id=tid,
                    state=state,
                    position_xy=pos,
                    velocity_xy=vel,
                    covariance=cov,
                    stamp_s=float(t_out[i]),
                    created_s=float(self._created[i]),
                    last_seen_s=float(self._last_seen[i]),
                    hits=int(self._hits[i]),
                    cameras=frozenset(c for c, t in aux.cameras.items() if t >= window_start),
                    height_m=aux.height_m,
                    associated=tuple(self._last_assoc.get(tid, ())),
                )
            )
        return out

    # ------------------------------------------------------------------ clock admission
    def _admit(self, stamp: float) -> tuple[FrameStatus, bool, tuple[int, ...]]:
        """Classify a frame stamp against the clock; handle the clock-jump resync rule."""
        if self._clock is None:
            self._reject_run = 0
            return FrameStatus.APPLIED, False, ()
        cfg = self._cfg
        if stamp > self._clock + cfg.max_future_stamp_s + _EPS_S:
            direction = 1
        elif stamp < self._clock - cfg.max_detection_delay_s - _EPS_S:
            direction = -1
        else:
            self._reject_run = 0
            late = stamp < self._clock
            return (FrameStatus.APPLIED_LATE if late else FrameStatus.APPLIED), False, ()

        self._reject_run = self._reject_run + 1 if direction == self._reject_dir else 1
        self._reject_dir = direction
        if cfg.clock_resync_frames and self._reject_run >= cfg.clock_resync_frames:
            self._reject_run = 0
            self._stats.clock_resyncs += 1
            if direction > 0:  # idle gap: time simply passed; lifecycle timeouts apply normally
                return FrameStatus.APPLIED, True, ()
            return FrameStatus.APPLIED, True, self.reset()  # time went backwards: start afresh
        if direction > 0:
            self._stats.frames_rejected_future += 1
            return FrameStatus.REJECTED_FUTURE, False, ()
        self._stats.frames_rejected_late += 1
        return FrameStatus.REJECTED_LATE, False, ()

    # ------------------------------------------------------------------ association
    def _associate(
        self, z: FloatArray, r2: FloatArray, stamp: float
    ) -> tuple[
        NDArray[np.intp], NDArray[np.intp], FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.bool_]
    ]:
        """GNN assignment of detections to tracks predicted to ``stamp``.

        Returns matched track rows / detection columns, the predicted states, the mask of tracks
        predicted from history (late frame) and the mask of detections near some track.
        """
        late = self._t > stamp
        if late.any():
            x_a, P_a, t_a = self._x.copy(), self._P.copy(), self._t.copy()
            for i in np.flatnonzero(late):
                aux = self._aux[i]
                k = bisect.bisect_right(aux.stamps, stamp) - 1
                entry = aux.history[max(k, 0)]  # k < 0: track born after the frame -> retrodict
                t_a[i], x_a[i], P_a[i] = entry[0], entry[3], entry[4]
        else:
            x_a, P_a, t_a = self._x, self._P, self._t
        x_pred, P_pred = self._model.predict(x_a, P_a, stamp - t_a)
        d2, log_det = mahalanobis_sq(x_pred[:, :2], P_pred[:, :2, :2], z, r2)
        dist2 = ((z[None, :, :] - x_pred[:, None, :2]) ** 2).sum(axis=2)
        close = dist2 < self._cfg.min_person_separation_m**2
        near = close.any(axis=0)
        # Tracks are served in a cascade (as DeepSORT's matching cascade): CONFIRMED tracks detected
        # within coast_after_s, then the other CONFIRMED ones, then LOST, then TENTATIVE, so that
        # neither a coasting track whose person is gone nor a tentative duplicate takes the
        # detection of a person whose track is healthy.  In each group:
        # Pass 1: GNN inside the chi-square gate on the squared Mahalanobis distance (and the metric
        # gate); the cost is d2 + log det S (negative log-likelihood), with d2 alone a vague track
        # looks "closer" than a precise one.
        # Pass 2 (not for LOST tracks): a leftover detection within
        # min_person_separation_m of a leftover track's predicted position (nobody else can be so
        # close), or inside the wider chi-square gate of probability 1 - (1 - gate_probability)**2
        # (= twice the d2 gate for 2 dof), or within reach of its last measured position
        # (min_person_separation_m + max_speed_mps * time since then, at most max_gate_distance_m),
        # is that person: the constant-velocity gate alone loses people who turn or stop, and noise
        # outliers.
        cfg = self._cfg
        feasible = (d2 <= self._gate) & (dist2 <= cfg.max_gate_distance_m**2)
        nll = d2 + log_det
        free_c = np.ones(d2.shape[1], dtype=bool)
        rows_l: list[NDArray[np.intp]] = []
        cols_l: list[NDArray[np.intp]] = []
        confirmed = self._state == _CONFIRMED
        fresh = stamp - t_a < cfg.coast_after_s
        groups = (
            (confirmed & fresh, True),
            (confirmed & ~fresh, True),
            (self._state == _LOST, False),
            (self._state == _TENTATIVE, True),
        )
        for group, second_pass in groups:
            if not group.any() or not free_c.any():
                continue
            r_, c_ = _gnn(nll, feasible & group[:, None] & free_c[None, :])
            rows_l.append(r_)
            cols_l.append(c_)
            free_c[c_] = False
            if not second_pass or not free_c.any():
                continue
            group[r_] = False
            left_r = np.flatnonzero(group)
            if left_r.shape[0] == 0:
                continue
            t_last = self._t[left_r].copy()
            z_last = self._zmeas[left_r].copy()
            for k in np.flatnonzero(t_last > stamp):  # late frame: measurement before it
                t_last[k], z_last[k] = self._last_measurement(int(left_r[k]), stamp)
            reach = np.minimum(
                cfg.min_person_separation_m + cfg.max_speed_mps * np.maximum(stamp - t_last, 0.0),
                max(cfg.max_gate_distance_m, cfg.min_person_separation_m),
            )
            dist2_last = ((z[None, :, :] - z_last[:, None, :]) ** 2).sum(axis=2)
            near_pred = (close[left_r] | (d2[left_r] <= 2.0 * self._gate)) & (
                dist2[left_r] <= cfg.max_gate_distance_m**2
            )
            ok2 = (near_pred | (dist2_last < reach[:, None] ** 2)) & free_c[None, :]
            if ok2.any():
                r_, c_ = _gnn(np.minimum(dist2[left_r], dist2_last), ok2)
                rows_l.append(left_r[r_])
                cols_l.append(c_)
                free_c[c_] = False
        empty = np.zeros(0, dtype=np.intp)
        rows = np.concatenate(rows_l) if rows_l else empty
        cols = np.concatenate(cols_l) if cols_l else empty
        return rows, cols, x_pred, P_pred, late, near

    def _last_measurement(self, i: int, stamp: float) -> tuple[float, FloatArray]:
        """Stamp and position of track ``i``'s newest measurement at or before ``stamp``.

        (Its first measurement if the track was born after ``stamp``.)
        """
        aux = self._aux[i]
        if aux.stamps[-1] <= stamp:
            entry = aux.history[-1]
        else:
            entry = aux.history[max(bisect.bisect_right(aux.stamps, stamp) - 1, 0)]
        return entry[0], entry[1]

    def _new_track_candidates(self, z: FloatArray, cols: NDArray[np.intp]) -> NDArray[np.intp]:
        """Greedily keep candidate detections at least ``min_person_separation_m`` from each other."""
        if cols.shape[0] < 2:
            return cols
        zc = z[cols]
        d2 = ((zc[:, None, :] - zc[None, :, :]) ** 2).sum(axis=2)
        close = d2 < self._cfg.min_person_separation_m**2
        if close.sum() == cols.shape[0]:  # only the diagonal
            return cols
        keep: list[int] = []
        for k in range(cols.shape[0]):
            if not any(close[k, j] for j in keep):
                keep.append(k)
        return cols[keep]

    def _apply_matches(
        self,
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
        x_pred: FloatArray,
        P_pred: FloatArray,
        late: NDArray[np.bool_],
        z: FloatArray,
        r2: FloatArray,
        valid: NDArray[np.intp],
        detections: Sequence[Detection],
        stamp: float,
        camera_id: str,
    ) -> None:
        """Kalman-update matched tracks and their bookkeeping."""
        if rows.shape[0] == 0:
            return
        in_order = ~late[rows]
        r_io, c_io = rows[in_order], cols[in_order]
        cutoff = self._prune_cutoff()
        if r_io.shape[0]:
            z_io = z[c_io]
            r2_io = r2[c_io]
            x_new, P_new = self._model.update(x_pred[r_io], P_pred[r_io], z_io, r2_io)
            self._x[r_io] = x_new
            self._P[r_io] = P_new
            self._t[r_io] = stamp
            self._zmeas[r_io] = z_io
            aux_all = self._aux
            for k, (i, r2_k) in enumerate(zip(r_io.tolist(), r2_io.tolist(), strict=True)):
                aux = aux_all[i]
                aux.history.append((stamp, z_io[k], r2_k, x_new[k], P_new[k]))
                aux.stamps.append(stamp)
                if len(aux.stamps) > 2 and aux.stamps[1] < cutoff:
                    self._prune(aux, cutoff)
        if r_io.shape[0] < rows.shape[0]:
            self._insert_late(rows[~in_order], cols[~in_order], x_pred, P_pred, z, r2, stamp, cutoff)
        self._last_seen[rows] = np.maximum(self._last_seen[rows], stamp)
        self._created[rows] = np.minimum(self._created[rows], stamp)
        self._hits[rows] += 1
        ids = self._ids[rows].tolist()
        for i, d_idx, tid in zip(rows.tolist(), valid[cols].tolist(), ids, strict=True):
            det = detections[d_idx]
            aux = self._aux[i]
            if aux.cameras.get(camera_id, -math.inf) < stamp:
                aux.cameras[camera_id] = stamp
            if det.height_m == det.height_m and stamp >= aux.height_stamp_s:  # finite (not NaN)
                aux.height_m, aux.height_stamp_s = det.height_m, stamp
            self._last_assoc.setdefault(tid, []).append((d_idx, det.embedding))

    def _insert_late(
        self,
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
        x_pred: FloatArray,
        P_pred: FloatArray,
        z: FloatArray,
        r2: FloatArray,
        stamp: float,
        cutoff: float,
    ) -> None:
        """Insert late measurements into the matched tracks' histories and re-filter the later steps.

        ``x_pred`` / ``P_pred`` rows are the tracks' anchors (newest posterior before ``stamp``)
        predicted to ``stamp``; a track born after ``stamp`` is re-initialised from the late
        detection instead.  The re-filtering is batched across tracks, one step at a time.
        """
        model = self._model
        rows_l = rows.tolist()
        hists = [self._aux[i] for i in rows_l]
        ks = [bisect.bisect_right(aux.stamps, stamp) for aux in hists]
        zc, r2c = z[cols], r2[cols]
        x_new, P_new = model.update(x_pred[rows], P_pred[rows], zc, r2c)
        born_after = np.array([k == 0 for k in ks])
        if born_after.any():  # earlier than the track's first detection: it becomes the new first one
            x_new[born_after], P_new[born_after] = model.initial_state(zc[born_after], r2c[born_after])
        r2_list = r2c.tolist()
        for n, (aux, k) in enumerate(zip(hists, ks, strict=True)):
            aux.history.insert(k, (stamp, zc[n], r2_list[n], x_new[n], P_new[n]))
            aux.stamps.insert(k, stamp)
        prev_x, prev_P = x_new.copy(), P_new.copy()  # working copies: history keeps x_new's rows
        prev_t = np.full(len(rows_l), stamp)
        pos = ks
        while True:
            todo = [n for n, aux in enumerate(hists) if pos[n] + 1 < len(aux.history)]
            if not todo:
                break
            entries = [hists[n].history[pos[n] + 1] for n in todo]
            idx = np.array(todo)
            t_e = np.array([e[0] for e in entries])
            xp, Pp = model.predict(prev_x[idx], prev_P[idx], t_e - prev_t[idx])
            xu, Pu = model.update(
                xp, Pp, np.array([e[1] for e in entries]), np.array([e[2] for e in entries])
            )
            for m, n in enumerate(todo):
                pos[n] += 1
                e = entries[m]
                hists[n].history[pos[n]] = (e[0], e[1], e[2], xu[m], Pu[m])
            prev_x[idx], prev_P[idx], prev_t[idx] = xu, Pu, t_e
        for i, aux in zip(rows_l, hists, strict=True):
            head = aux.history[-1]
            self._t[i], self._zmeas[i], self._x[i], self._P[i] = head[0], head[1], head[3], head[4]
            self._prune(aux, cutoff)

    def _prune_cutoff(self) -> float:
        """History older than this is not needed any more (late frames beyond it are rejected)."""
        clock = self._clock if self._clock is not None else -math.inf
        return clock - self._cfg.max_detection_delay_s - _PRUNE_MARGIN_S

    @staticmethod
    def _prune(aux: _Aux, cutoff: float) -> None:
        """Drop history older than ``cutoff``, keeping the newest posterior before it as anchor."""
        k = bisect.bisect_left(aux.stamps, cutoff) - 1
        if k > 0:
            del aux.history[:k]
            del aux.stamps[:k]

    def _create(
        self,
        z: FloatArray,
        r2: FloatArray,
        det_idx: NDArray[np.intp],
        detections: Sequence[Detection],
        stamp: float,
        camera_id: str,
    ) -> list[int]:
        """Start TENTATIVE tracks from unmatched detections; returns their ids."""
        k = z.shape[0]
        x0, P0 = self._model.initial_state(z, r2)
        ids = list(range(self._next_id, self._next_id + k))
        self._next_id += k
        self._ids = np.concatenate([self._ids, np.array(ids, dtype=np.int64)])
        self._state = np.concatenate([self._state, np.full(k, _TENTATIVE, dtype=np.int8)])
        self._created = np.concatenate([self._created, np.full(k, stamp)])
        self._last_seen = np.concatenate([self._last_seen, np.full(k, stamp)])
        self._hits = np.concatenate([self._hits, np.ones(k, dtype=np.int64)])
        self._x = np.concatenate([self._x, x0])
        self._P = np.concatenate([self._P, P0])
        self._t = np.concatenate([self._t, np.full(k, stamp)])
        self._zmeas = np.concatenate([self._zmeas, z])
        for j in range(k):
            det = detections[int(det_idx[j])]
            h = det.height_m
            aux = _Aux(
                history=[(stamp, z[j], float(r2[j]), x0[j], P0[j])],
                stamps=[stamp],
                cameras={camera_id: stamp},
                height_m=h,
                height_stamp_s=stamp if math.isfinite(h) else -math.inf,
            )
            self._aux.append(aux)
            self._last_assoc[ids[j]] = [(int(det_idx[j]), det.embedding)]
        self._stats.tracks_created += k
        return ids

    # ------------------------------------------------------------------ lifecycle
    def _tick(self) -> tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...], tuple[int, ...]]:
        """Apply lifecycle transitions at the clock; returns (confirmed, lost, recovered, deleted) ids."""
        if self._ids.shape[0] == 0 or self._clock is None:
            return (), (), (), ()
        cfg = self._cfg
        now = self._clock
        state = self._state
        unseen = now - self._last_seen
        tent = state == _TENTATIVE
        # A tentative track next to a confirmed one is a duplicate of that person (see
        # min_person_separation_m): drop it rather than let it confirm.
        merged = np.zeros_like(tent)
        established = state == _CONFIRMED
        if tent.any() and established.any():
            pos = self._x[:, :2] + self._x[:, 2:] * (now - self._t)[:, None]
            gap2 = ((pos[tent][:, None, :] - pos[established][None, :, :]) ** 2).sum(axis=2)
            merged[tent] = (gap2 < cfg.min_person_separation_m**2).any(axis=1)
            self._stats.tracks_merged += int(merged.sum())
        conf = (
            tent
            & ~merged
            & (self._hits >= cfg.detections_to_confirm)
            & (self._last_seen - self._created <= cfg.confirm_window_s + _EPS_S)
        )
        state[conf] = _CONFIRMED
        lost = (state == _CONFIRMED) & (unseen >= cfg.lost_after_s - _EPS_S)
        recovered = (state == _LOST) & (unseen < cfg.lost_after_s - _EPS_S)
        state[lost] = _LOST
        state[recovered] = _CONFIRMED
        dead = merged | self._expired(now)
        ids = self._ids
        confirmed_ids = tuple(int(i) for i in ids[conf])
        lost_ids = tuple(int(i) for i in ids[lost & ~dead])
        recovered_ids = tuple(int(i) for i in ids[recovered])
        self._stats.tracks_confirmed += len(confirmed_ids)
        deleted_ids = self._delete(dead)
        return confirmed_ids, lost_ids, recovered_ids, deleted_ids

    def _expired(self, now: float) -> NDArray[np.bool_]:
        """Tracks timed out at ``now``: unconfirmed past the window, or unseen lost+delete seconds."""
        cfg = self._cfg
        state = self._state
        return ((state == _TENTATIVE) & (now - self._created > cfg.confirm_window_s + _EPS_S)) | (
            (state != _TENTATIVE) & (now - self._last_seen >= cfg.lost_after_s + cfg.delete_after_s - _EPS_S)
        )

    def _delete(self, dead: NDArray[np.bool_]) -> tuple[int, ...]:
        """Remove the ``dead`` tracks; returns their ids."""
        if not dead.any():
            return ()
        deleted_ids = tuple(int(i) for i in self._ids[dead])
        self._stats.tracks_deleted += len(deleted_ids)
        keep = ~dead
        self._ids = self._ids[keep]
        self._state = self._state[keep]
        self._created = self._created[keep]
        self._last_seen = self._last_seen[keep]
        self._hits = self._hits[keep]
        self._x = self._x[keep]
        self._P = self._P[keep]
        self._t = self._t[keep]
        self._zmeas = self._zmeas[keep]
        self._aux = [a for a, k in zip(self._aux, keep, strict=True) if k]
        return deleted_ids
