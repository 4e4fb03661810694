"""Multi-camera people tracker of the master node (pure core, no ROS).

People are tracked on the world ground plane with one constant-velocity Kalman filter per person
(:mod:`~face_reid_master.tracking.kalman`), global-nearest-neighbour association on the
Mahalanobis distance gated at the chi-square quantile (:mod:`~face_reid_master.tracking.association`)
and a TENTATIVE -> CONFIRMED -> LOST -> DELETED lifecycle (:mod:`~face_reid_master.tracking.lifecycle`),
as in OpenPTrack (Koide et al. 2017, Sec. III-A).  A person who leaves every view gets a new track id
on return; restoring the identity is the face table's job.

Time is data-driven (:mod:`~face_reid_master.tracking.admission`): the clock is the newest accepted
frame stamp, each camera frame is applied at once, and a frame older than the clock but within
``max_detection_delay_s`` is applied *exactly* (:mod:`~face_reid_master.tracking.history`).
Decisions already reported (earlier associations, created/deleted ids) are never revised.  The
single approximation: a late detection is gated against a track *born after* it by predicting that
track's first state backwards.

Inputs come validated from MasterCore: positions finite, stds finite and > 0.  The tracker does not
re-check them (it only rejects late / future stamps, which is tracking logic).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import check_real, check_stamp
from face_reid_camera.common.stamp_admission import ClockVerdict, StampClock
from face_reid_master.tracking.admission import Clock, verdict_on
from face_reid_master.tracking.appearance import AppearanceGallery, appearance_distances
from face_reid_master.tracking.association import Associator, Matches
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.history import FilterStep, TrackHistory, insert_late, record_updates
from face_reid_master.tracking.interface import FrameDetections
from face_reid_master.tracking.lifecycle import EPS_S, birth_candidates, expired, transitions
from face_reid_master.tracking.records import (
    Detection,
    FrameStatus,
    TrackerStats,
    TrackSnapshot,
    TrackState,
    UpdateResult,
)
from face_reid_master.tracking.track_table import TrackTable

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
IndexArray = NDArray[np.intp]

_PRUNE_MARGIN_S = 1e-6  # history kept slightly beyond max_detection_delay_s
_DUE_MARGIN_S = 1e-6  # lifecycle checks start this much before a transition is due (rounding of the time tests)
_TENTATIVE = int(TrackState.TENTATIVE)
_LOST = int(TrackState.LOST)
_NO_INDEX = np.zeros(0, dtype=np.intp)


class Tracker:
    """Multi-camera GNN + Kalman people tracker on the world ground plane.

    Call :meth:`update_arrays` (or :meth:`update`) once per camera frame (any order within
    ``max_detection_delay_s``), read :meth:`snapshots` to publish.  Not thread-safe.
    """

    def __init__(self, config: TrackerConfig | None = None, clock: StampClock | None = None) -> None:
        if config is None:
            config = TrackerConfig()
        if not isinstance(config, TrackerConfig):
            raise ValueError(f"config must be a TrackerConfig, got {type(config).__name__}")
        self._cfg = config
        self._model = config.motion_model
        self._associate = Associator(config)
        self._clock = Clock(config) if clock is None else clock
        self._stats = TrackerStats()
        self._next_id = 1
        self._clear_arrays()

    def _clear_arrays(self) -> None:
        self._tab = TrackTable()
        self._camera_frames: dict[str, float] = {}  # camera id -> stamp of its newest frame applied
        self._quiet_until = -math.inf  # no lifecycle transition can fall due before this stamp

    # ------------------------------------------------------------------ read-only properties
    @property
    def config(self) -> TrackerConfig:
        return self._cfg

    @property
    def stats(self) -> TrackerStats:
        return replace(self._stats)

    @property
    def clock(self) -> StampClock:
        """The clock stamps are judged against (the newest applied stamp): the core's stamp gate's own."""
        return self._clock

    @property
    def clock_s(self) -> float | None:
        """Newest accepted stamp (None before the first frame)."""
        return self._clock.now

    @property
    def num_tracks(self) -> int:
        return int(self._tab.ids.shape[0])

    def track_ids(self) -> list[int]:
        return [int(i) for i in self._tab.ids]

    # ------------------------------------------------------------------ entry points
    def update(self, detections: Sequence[Detection], stamp_s: float, camera_id: str) -> UpdateResult:
        """:meth:`update_arrays` for a sequence of :class:`Detection` (indices are into ``detections``)."""
        if len(detections):
            positions = np.array([d.position_xy for d in detections], dtype=np.float64)
            stds = np.array([d.position_std_m for d in detections], dtype=np.float64)
            heights = np.array([d.height_m for d in detections], dtype=np.float64)
        else:
            positions, stds, heights = np.zeros((0, 2)), np.zeros(0), np.zeros(0)
        return self.update_arrays(positions, stds, heights, stamp_s, camera_id)

    def update_frame(self, detections: FrameDetections, stamp_s: float, camera_id: str, *,
                     resync_backward: bool = True, admitted: ClockVerdict | None = None) -> UpdateResult:
        """The :class:`~face_reid_master.tracking.interface.MultiCameraTracker` entry: :meth:`update_arrays` on
        a frame's detection arrays."""
        d = detections
        return self.update_arrays(d.positions, d.stds, d.heights, stamp_s, camera_id, d.appearance, resync_backward,
                                  admitted)

    def update_arrays(
        self, positions: FloatArray, stds: FloatArray, heights: FloatArray, stamp_s: float, camera_id: str,
        appearance: NDArray[np.float32] | None = None, resync_backward: bool = True,
        admitted: ClockVerdict | None = None,
    ) -> UpdateResult:
        """Fuse one camera frame seen by ``camera_id`` at ``stamp_s`` (seconds).

        ``positions`` (N, 2) world ground-plane positions, ``stds`` (N,) their isotropic stds,
        ``heights`` (N,) head heights (nan = unknown), all validated by the caller; ``appearance`` (N, r):
        body-appearance embeddings in the learned metric's space (NaN rows = not described; None = none).
        ``resync_backward`` False: a run of late frames is refused, never taken for a clock jump back (which
        deletes every track). Detection indices in the result are rows of these arrays.  ValueError on a
        non-finite stamp. ``admitted``: the verdict of the gate owning this tracker's ``clock``: not judged again.
        """
        stamp = check_stamp(stamp_s)
        status, resync, deleted_by_reset = self._admit(stamp, resync_backward, admitted)
        if status in (FrameStatus.REJECTED_LATE, FrameStatus.REJECTED_FUTURE):
            return UpdateResult(stamp, camera_id, status)
        stats = self._stats
        stats.frames_processed += 1
        stats.frames_out_of_order += status is FrameStatus.APPLIED_LATE
        stats.detections_received += positions.shape[0]
        expired_ids = self._expire_before(stamp)  # timed-out tracks must not take this frame's detections
        r2 = stds**2
        if appearance is not None and not np.isfinite(appearance).any():
            appearance = None
        matched = self._match(positions, r2, stamp, appearance, camera_id)
        self._camera_frames[camera_id] = max(self._camera_frames.get(camera_id, -math.inf), stamp)
        self._update_matched(matched, positions, r2, heights, stamp, camera_id)
        rows, cols = matched.matches.rows, matched.matches.cols
        associations = list(zip(self._tab.ids[rows].tolist(), cols.tolist(), strict=True))
        created, created_cols, suppressed, dropped = self._initiate(matched, positions, r2, heights, stamp, camera_id)
        if appearance is not None:
            self._tab.remember_looks(appearance, rows, cols, created_cols)
        associations.extend(zip(created, created_cols, strict=True))
        self._clock.follow(stamp)
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
            deleted=deleted_by_reset + expired_ids + deleted,
            rejected_detections=tuple(dropped),
            suppressed_detections=tuple(suppressed),
            clock_resync=resync,
            swaps=matched.matches.swaps,
            strays=matched.matches.strays,
        )

    def advance(self, stamp_s: float) -> UpdateResult:
        """Move the clock forward to ``stamp_s`` without detections and apply lifecycle timeouts.

        For a node timer when no camera frames arrive; a stamp not newer than the clock is a no-op.
        Note that frames older than ``stamp_s - max_detection_delay_s`` will then be rejected.
        """
        stamp = check_stamp(stamp_s)
        if self._clock.now is not None and stamp <= self._clock.now:
            return UpdateResult(stamp, "", FrameStatus.ADVANCED)
        self._clock.follow(stamp)
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
        deleted = tuple(int(i) for i in self._tab.ids)
        self._stats.tracks_deleted += len(deleted)
        self._clear_arrays()
        self._clock.reset()
        return deleted

    def reserve_id(self) -> int:
        """A fresh id no track will be given (ids are never reused): the new published id of a split track."""
        self._next_id += 1
        return self._next_id - 1

    def snapshots(self, at_s: float | None = None, include_tentative: bool = True) -> list[TrackSnapshot]:
        """Snapshots of the live tracks, sorted by id, states predicted forward to ``at_s``.

        ``at_s`` defaults to the clock; a track whose newest posterior is later than ``at_s`` is
        reported at its own stamp (never predicted backwards).
        """
        n = self._tab.ids.shape[0]
        if n == 0:
            return []
        clock = self._clock.now
        at = clock if at_s is None else check_real("at_s", at_s)
        assert at is not None
        t_out = np.maximum(self._tab.t, at)
        x, P = self._model.predict(self._tab.x, self._tab.P, t_out - self._tab.t)
        x.flags.writeable = False  # fresh arrays: the snapshots hold read-only views of them
        P.flags.writeable = False
        window_start = (clock if clock is not None else at) - self._cfg.camera_window_s - EPS_S
        return self._tab.snapshots(x, P, t_out, window_start, include_tentative)

    # ------------------------------------------------------------------ steps of update_arrays
    def _admit(self, stamp: float, resync_backward: bool, admitted: ClockVerdict | None) -> tuple[FrameStatus, bool,
                                                                                                 tuple[int, ...]]:
        """The stamp's verdict (admission.verdict_on), counted; on a backward clock jump delete everything."""
        verdict = verdict_on(self._clock, stamp, resync_backward, admitted)
        stats = self._stats
        if verdict.status is FrameStatus.REJECTED_FUTURE:
            stats.frames_rejected_future += 1
        elif verdict.status is FrameStatus.REJECTED_LATE:
            stats.frames_rejected_late += 1
        stats.clock_resyncs += verdict.resync
        return verdict.status, verdict.resync, self.reset() if verdict.reset else ()

    def _expire_before(self, stamp: float) -> tuple[int, ...]:
        """Delete the tracks that time out by ``stamp`` when it is newer than the clock."""
        clock = self._clock.now
        if clock is None or stamp <= clock or not self._tab.ids.shape[0] or stamp < self._quiet_until:
            return ()
        return self._delete(expired(self._tab.state, self._tab.created, self._tab.last_seen, stamp, self._cfg))

    def _anchors(
        self, stamp: float, late: NDArray[np.bool_]
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Each track's newest posterior at or before ``stamp`` (x, P, its stamp, its measurement).

        Only the ``late`` tracks (newest posterior after ``stamp``) need their history; a track born
        after ``stamp`` gives its first step.
        """
        if not late.any():
            return self._tab.x, self._tab.P, self._tab.t, self._tab.zmeas
        x_a, P_a, t_a, z_a = self._tab.x.copy(), self._tab.P.copy(), self._tab.t.copy(), self._tab.zmeas.copy()
        for i in np.flatnonzero(late).tolist():
            step = self._tab.hist[i].anchor(stamp)
            t_a[i], z_a[i], x_a[i], P_a[i] = step.stamp_s, step.z, step.x, step.P
        return x_a, P_a, t_a, z_a

    def _match(self, z: FloatArray, r2: FloatArray, stamp: float, appearance: NDArray[np.float32] | None,
               camera_id: str) -> _Matched:
        """Associate the detections with the tracks that could take one (:meth:`_candidates`), predicted."""
        m = z.shape[0]
        if m == 0 or self._tab.ids.shape[0] == 0:
            return _Matched(Matches(_NO_INDEX, _NO_INDEX, np.zeros(m, dtype=bool)), None, None, None)
        late = self._tab.t > stamp
        x_a, P_a, t_a, z_a = self._anchors(stamp, late)
        cand = self._candidates(x_a, t_a, z_a, z, stamp, reattach=appearance is not None)
        if cand.shape[0] == 0:
            return _Matched(Matches(_NO_INDEX, _NO_INDEX, np.zeros(m, dtype=bool)), None, None, None)
        looks = alike = None
        if appearance is not None:  # every track's distances: pass 3 needs how many tracks look alike
            looks_all = appearance_distances(self._tab.looks, appearance)
            alike = (looks_all < self._cfg.appearance_match_distance).sum(axis=0)  # NaN compares False
            looks = looks_all[cand]
        x_pred, P_pred = self._model.predict(x_a[cand], P_a[cand], stamp - t_a[cand])
        hidden = self._tab.hidden(cand, camera_id, self._camera_frames.get(camera_id, math.inf), stamp,
                                  self._cfg.stray_occlusion_max_s)
        local = self._associate(x_pred, P_pred, self._tab.state[cand], t_a[cand], z_a[cand], z, r2, stamp, looks, alike,
                                hidden)
        rows = local.rows
        ids = self._tab.ids[cand]
        swaps = tuple((int(ids[a]), int(ids[b]), p) for a, b, p in local.swaps)
        strays = tuple((int(ids[a]), p) for a, p in local.strays)
        return _Matched(Matches(cand[rows], local.cols, local.near, swaps, strays), x_pred[rows], P_pred[rows], late)

    def _candidates(self, x_a: FloatArray, t_a: FloatArray, z_a: FloatArray, z: FloatArray, stamp: float,
                    reattach: bool) -> IndexArray:
        """Tracks that some detection could join in a pass of the association: within ``max_gate_distance_m``
        (or ``min_person_separation_m``) of the predicted position, or within walking reach of the last
        detection (capped as in pass 2; uncapped for LOST tracks when pass 3 can re-attach them)."""
        cfg = self._cfg
        dt = stamp - t_a
        mean = x_a[:, :2] + dt[:, None] * x_a[:, 2:]  # the predicted position, as the Kalman prediction makes it
        radius = max(cfg.max_gate_distance_m, cfg.min_person_separation_m)  # also the cap of pass 2's reach
        reach = cfg.min_person_separation_m + cfg.max_speed_mps * np.maximum(dt, 0.0)
        reach = np.where(reattach & (self._tab.state == _LOST), reach, np.minimum(reach, radius))
        near_pred = (((z[None, :, :] - mean[:, None, :]) ** 2).sum(axis=2) <= radius * radius).any(axis=1)
        near_last = (((z[None, :, :] - z_a[:, None, :]) ** 2).sum(axis=2) < (reach * reach)[:, None]).any(axis=1)
        return np.flatnonzero(near_pred | near_last)

    def _update_matched(
        self,
        matched: _Matched,
        z: FloatArray,
        r2: FloatArray,
        heights: FloatArray,
        stamp: float,
        camera_id: str,
    ) -> None:
        """Kalman-update the matched tracks (late ones through their history) and their bookkeeping."""
        rows, cols = matched.matches.rows, matched.matches.cols
        if rows.shape[0] == 0:
            return
        x_pred, P_pred, late = matched.x_pred, matched.P_pred, matched.late
        assert x_pred is not None and P_pred is not None and late is not None
        in_order = ~late[rows]
        r_io, c_io = rows[in_order], cols[in_order]
        cutoff = self._prune_cutoff()
        if r_io.shape[0]:
            z_io = z[c_io]
            r2_io = r2[c_io]
            x_new, P_new = self._model.update(x_pred[in_order], P_pred[in_order], z_io, r2_io)
            self._tab.x[r_io] = x_new
            self._tab.P[r_io] = P_new
            self._tab.t[r_io] = stamp
            self._tab.zmeas[r_io] = z_io
            hist = self._tab.hist
            record_updates([hist[i] for i in r_io.tolist()], stamp, z_io, r2_io.tolist(), x_new, P_new, cutoff)
        if r_io.shape[0] < rows.shape[0]:
            r_late, c_late = rows[~in_order], cols[~in_order]
            heads = insert_late(
                self._model,
                [self._tab.hist[i] for i in r_late.tolist()],
                stamp,
                z[c_late],
                r2[c_late],
                x_pred[~in_order],
                P_pred[~in_order],
                cutoff,
            )
            for i, head in zip(r_late.tolist(), heads, strict=True):
                tab = self._tab
                tab.t[i], tab.zmeas[i], tab.x[i], tab.P[i] = head.stamp_s, head.z, head.x, head.P
        if (self._tab.state[rows] == _LOST).any():
            self._quiet_until = -math.inf  # recovered at the next tick
        self._tab.detected(rows, heights[cols], stamp, camera_id)
        self._stats.detections_associated += int(rows.shape[0])

    def _initiate(
        self,
        matched: _Matched,
        z: FloatArray,
        r2: FloatArray,
        heights: FloatArray,
        stamp: float,
        camera_id: str,
    ) -> tuple[list[int], list[int], list[int], list[int]]:
        """Start TENTATIVE tracks from the leftover detections not too close to a track or each other.

        Returns the new ids, their detection indices, the suppressed indices (duplicates of a tracked
        person) and those dropped at the ``max_tracks`` limit.
        """
        unmatched = np.ones(z.shape[0], dtype=bool)
        unmatched[matched.matches.cols] = False
        if not unmatched.any():
            return [], [], [], []
        new_cols = birth_candidates(
            z, np.flatnonzero(unmatched & ~matched.matches.near), self._cfg.min_person_separation_m
        )
        suppressed = np.setdiff1d(np.flatnonzero(unmatched), new_cols)
        self._stats.detections_suppressed_near_track += int(suppressed.shape[0])
        room = max(0, self._cfg.max_tracks - int(self._tab.ids.shape[0]))
        dropped = new_cols[room:]
        self._stats.detections_dropped_track_limit += int(dropped.shape[0])
        new_cols = new_cols[:room]
        created = []
        if new_cols.shape[0]:
            created = self._create(z[new_cols], r2[new_cols], heights[new_cols], stamp, camera_id)
        return created, new_cols.tolist(), suppressed.tolist(), sorted(dropped.tolist())

    def _prune_cutoff(self) -> float:
        """History older than this is not needed any more (late frames beyond it are rejected)."""
        clock = self._clock.now if self._clock.now is not None else -math.inf
        return clock - self._cfg.max_detection_delay_s - _PRUNE_MARGIN_S

    def _create(
        self, z: FloatArray, r2: FloatArray, heights: FloatArray, stamp: float, camera_id: str
    ) -> list[int]:
        """Append TENTATIVE tracks started at detections ``z`` (k, 2); returns their ids."""
        k = z.shape[0]
        x0, P0 = self._model.initial_state(z, r2)
        ids = list(range(self._next_id, self._next_id + k))
        self._next_id += k
        self._tab.append(
            ids=ids, state=np.full(k, _TENTATIVE), created=np.full(k, stamp), last_seen=np.full(k, stamp),
            hits=np.ones(k), x=x0, P=P0, t=np.full(k, stamp), zmeas=z,
            looks=[AppearanceGallery(self._cfg.appearance_gallery_size) for _ in range(k)],
            hist=[TrackHistory(steps=[FilterStep(stamp, z[j], r2_j, x0[j], P0[j])], stamps=[stamp],
                               cameras={camera_id: stamp}, height_m=h,
                               height_stamp_s=stamp if math.isfinite(h) else -math.inf)
                  for j, (h, r2_j) in enumerate(zip(heights.tolist(), r2.tolist(), strict=True))])
        self._stats.tracks_created += k
        self._quiet_until = -math.inf  # tentative tracks: confirmed, merged or expired at any tick
        return ids

    def _tick(self) -> tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...], tuple[int, ...]]:
        """Apply lifecycle transitions at the clock; returns (confirmed, lost, recovered, deleted) ids.

        Skipped while the clock is before ``_quiet_until`` (nothing can fall due: see :meth:`_next_due`)."""
        now = self._clock.now
        if self._tab.ids.shape[0] == 0 or now is None or now < self._quiet_until:
            return (), (), (), ()
        tab = self._tab
        tr = transitions(tab.state, tab.hits, tab.created, tab.last_seen, tab.x, tab.t, now, self._cfg)
        ids = tab.ids
        confirmed_ids = tuple(int(i) for i in ids[tr.confirmed])
        lost_ids = tuple(int(i) for i in ids[tr.lost])
        recovered_ids = tuple(int(i) for i in ids[tr.recovered])
        self._stats.tracks_merged += tr.merged
        self._stats.tracks_confirmed += len(confirmed_ids)
        deleted = self._delete(tr.dead)
        self._quiet_until = self._next_due()
        return confirmed_ids, lost_ids, recovered_ids, deleted

    def _next_due(self) -> float:
        """Earliest stamp at which a transition could fall due without a new detection (a little early): never
        while a track is tentative, else the first confirmed track to become LOST or LOST one to expire.  Later
        detections only postpone these; a LOST track detected or a new track resets it."""
        state = self._tab.state
        if state.shape[0] == 0:
            return math.inf
        if (state == _TENTATIVE).any():
            return -math.inf
        cfg = self._cfg
        wait = np.where(state == _LOST, cfg.lost_after_s + cfg.delete_after_s, cfg.lost_after_s)
        return float((self._tab.last_seen + wait).min()) - EPS_S - _DUE_MARGIN_S

    def _delete(self, dead: NDArray[np.bool_]) -> tuple[int, ...]:
        """Remove the ``dead`` tracks; returns their ids."""
        if not dead.any():
            return ()
        deleted_ids = tuple(int(i) for i in self._tab.ids[dead])
        self._stats.tracks_deleted += len(deleted_ids)
        self._tab.keep(~dead)
        return deleted_ids


@dataclass(frozen=True, slots=True)
class _Matched:
    """Association of one frame plus the predictions it used (None when there was nothing to match)."""

    matches: Matches
    x_pred: FloatArray | None  # the matched tracks' predictions, row k for matches.rows[k]
    P_pred: FloatArray | None
    late: NDArray[np.bool_] | None  # tracks predicted from their history (newest posterior after the frame)
