"""Run the master core over a recorded scenario and log what happened (the input of the metrics).

:func:`run_master` feeds the camera frames, in stamp order, to a fresh :class:`MasterCore` (``core.tick`` at a
regular period between frames, as the node's timer does) and records a :class:`RunLog`: for every detection
its true person, track id and face id right after its frame; for every track its detections' true people,
when it got which face id, the names it showed and its estimated path; for every face id the track that
created it. Pure: no rclpy.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.body.metric_file import BodyFeatureMetric, BodyMetricModel
from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.identity.confidence_map import ConfidenceMap
from face_reid_master.identity.likelihood import LikelihoodModel
from face_reid_master.records import STATE_CONFIRMED, CameraFrameRecord

__all__ = ["DEFAULT_TICK_PERIOD_S", "ProgressCallback", "RunLog", "TrackLog", "decision_thresholds", "progress_to",
           "run_master"]

DEFAULT_TICK_PERIOD_S = 0.2  # the node ticks at tick_rate_hz = 5 Hz

ProgressCallback = Callable[[int, int], None]


@dataclass
class TrackLog:
    """What happened to one track (all stamps in scenario seconds).

    ``gt_counts``: true person (-1 = false positive) -> detections associated with the track.
    ``assignments``: (stamp, face id, "new" | "known") in order (Algorithm 1 assigns once per track; a track
    whose lent face was taken while it was lost may be assigned again; a swapped track goes on under a new id,
    i.e. as another TrackLog).
    ``evidence`` / ``confidence``: per assignment, what decided it and the posterior it was taken at.
    ``names``: name -> first stamp it was shown on one of the track's detections. ``path``: (stamp, x, y)
    samples of the published estimate while CONFIRMED. ``face_gt``: (stamp, true person) of each detection
    with a face embedding.
    """

    track_id: int
    birth_s: float
    last_seen_s: float
    gt_counts: dict[int, int] = field(default_factory=dict)
    face_detections: int = 0
    first_face_s: float | None = None
    confirmed: bool = False
    assignments: list[tuple[float, int, str]] = field(default_factory=list)
    released_s: float | None = None
    names: dict[str, float] = field(default_factory=dict)
    path: list[tuple[float, float, float]] = field(default_factory=list)
    face_gt: list[tuple[float, int]] = field(default_factory=list)  # (stamp, true person) of face detections
    evidence: list[str] = field(default_factory=list)  # per assignment: "face" or "body" (what decided it)
    confidence: list[float] = field(default_factory=list)  # per assignment: identity_confidence at the decision
    published_s: float | None = None  # first frame after which the master published it (None: never seen so)

    @property
    def detections(self) -> int:
        return int(sum(self.gt_counts.values()))

    @property
    def true_person(self) -> int:
        """Majority true person of the associated detections, false positives (-1) ignored; -1 if none."""
        real = {g: n for g, n in self.gt_counts.items() if g >= 0}
        if not real:
            return -1
        return min(real, key=lambda g: (-real[g], g))  # ties: the smaller gt id (deterministic)

    @property
    def purity(self) -> float:
        """Fraction of the detections that belong to the true person (0 for a false-positive track)."""
        total = self.detections
        person = self.true_person
        return float(self.gt_counts.get(person, 0) / total) if total and person >= 0 else 0.0

    @property
    def first_assignment(self) -> tuple[float, int, str] | None:
        return self.assignments[0] if self.assignments else None

    @property
    def face_person(self) -> int:
        """Majority true person of the track's face detections (false positives ignored), i.e. whose face
        it fed into the identity layer; the track's :attr:`true_person` when it had no face detection."""
        return self.face_person_until(math.inf)

    def face_person_until(self, stamp_s: float) -> int:
        """:attr:`face_person` of the face detections up to ``stamp_s``; all of them if there were none."""
        counts = Counter(g for s, g in self.face_gt if g >= 0 and s <= stamp_s + 1e-9)
        if not counts:
            counts = Counter(g for _, g in self.face_gt if g >= 0)
        if not counts:
            return self.true_person
        return min(counts, key=lambda g: (-counts[g], g))


@dataclass
class RunLog:
    """Everything :func:`evaluate_run` needs from one run of the master core over a scenario.

    Per detection (flat arrays, D rows, in frame order): ``det_frame`` frame index, ``det_stamp_s``,
    ``det_gt`` true person (-1 false positive), ``det_track`` track id (-1: not associated, e.g. a
    suppressed duplicate or a rejected frame), ``det_face`` the track's face id right after the frame
    (0: none yet), ``det_name`` the index in ``names`` of the name its face had then (-1: none; empty =
    not recorded). ``faces``: face id -> (creation stamp, creating track id). ``days``: (day, start_s,
    end_s, gt ids) of the scenario (used to split cross-day re-identifications). ``det_published``: whether
    the detection's track was among the published tracks right after its frame (empty = not recorded: every
    tracked detection counts as published, e.g. a log made from published messages).
    """

    method: str
    tracks: dict[int, TrackLog]
    faces: dict[int, tuple[float, int]]
    det_frame: NDArray[np.int64]
    det_stamp_s: NDArray[np.float64]
    det_gt: NDArray[np.int64]
    det_track: NDArray[np.int64]
    det_face: NDArray[np.int64]
    n_frames: int = 0
    frames_rejected: int = 0
    days: tuple[tuple[int, float, float, tuple[int, ...]], ...] = ()
    master_stats: dict[str, int] = field(default_factory=dict)
    runtime_s: float = 0.0
    det_name: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    names: tuple[str, ...] = ()
    body_metric: BodyFeatureMetric | None = None  # the fused body metric the run embedded bodies with
    # evidence kind -> the posterior a decision of that kind had to exceed (the run's MasterConfig; empty: unknown)
    decision_thresholds: dict[str, float] = field(default_factory=dict)
    det_published: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        arrays = {k: getattr(self, k) for k in ("det_frame", "det_stamp_s", "det_gt", "det_track", "det_face")}
        sizes = {np.asarray(v).shape for v in arrays.values()}
        if len(sizes) != 1 or len(next(iter(sizes))) != 1:
            raise ValueError(f"RunLog detection arrays must be 1-D of one length, got shapes {sorted(sizes)}")
        for name, value in arrays.items():
            setattr(self, name, np.asarray(value, dtype=np.float64 if name == "det_stamp_s" else np.int64))
        self.det_name = np.asarray(self.det_name, dtype=np.int64)
        if self.det_name.size and (self.det_name.shape != self.det_frame.shape
                                   or int(self.det_name.max()) >= len(self.names)):
            raise ValueError("RunLog.det_name must have one index into names (or -1) per detection")
        self.det_published = np.asarray(self.det_published, dtype=bool)
        if self.det_published.size and self.det_published.shape != self.det_frame.shape:
            raise ValueError("RunLog.det_published must have one flag per detection (or none)")
        if not np.all(np.isfinite(self.det_stamp_s)):
            raise ValueError("RunLog.det_stamp_s contains NaN or Inf")
        if self.det_frame.size > 1 and np.any(np.diff(self.det_frame) < 0):
            raise ValueError("RunLog detections must be in frame order")



def _check_frames(frames: Sequence[CameraFrameRecord], frame_gt_ids: Sequence[NDArray[np.integer]]) -> None:
    if len(frames) != len(frame_gt_ids):
        raise ValueError(f"frames ({len(frames)}) and frame_gt_ids ({len(frame_gt_ids)}) differ in length")
    for i, (frame, gt) in enumerate(zip(frames, frame_gt_ids, strict=True)):
        if np.asarray(gt).shape != (len(frame.people),):
            raise ValueError(f"frame {i}: {len(frame.people)} people but gt ids of shape {np.asarray(gt).shape}")
        if not (isinstance(frame.stamp_s, int | float) and math.isfinite(frame.stamp_s)):
            raise ValueError(f"frame {i}: stamp_s must be a finite number, got {frame.stamp_s!r}")
        if i and frame.stamp_s < frames[i - 1].stamp_s:
            raise ValueError(f"frames must be in stamp order (frame {i} at {frame.stamp_s} s < previous)")


def run_master(
    frames: Sequence[CameraFrameRecord],
    frame_gt_ids: Sequence[NDArray[np.integer]],
    config: MasterConfig | None = None,
    *,
    likelihood: LikelihoodModel | None = None,
    body_metric: BodyMetricModel | None = None,
    confidence_map: ConfidenceMap | None = None,
    gallery: Mapping[str, NDArray[np.floating]] | None = None,
    tick_period_s: float = DEFAULT_TICK_PERIOD_S,
    days: Sequence[tuple[int, float, float, Sequence[int]]] = (),
    progress: ProgressCallback | None = None,
) -> RunLog:
    """Run a fresh MasterCore (no store) over ``frames`` in order and record a :class:`RunLog`.

    ``frame_gt_ids[i][j]`` is the true person of ``frames[i].people[j]``. ``core.tick`` runs every
    ``tick_period_s`` of scenario time between frames (timeouts without frames) and the published tracks
    are sampled at those instants (paths, confirmation). Frames are passed without ``now_s`` (replay).
    """
    if not (isinstance(tick_period_s, int | float) and math.isfinite(tick_period_s) and tick_period_s > 0):
        raise ValueError(f"tick_period_s must be a finite number > 0, got {tick_period_s!r}")
    _check_frames(frames, frame_gt_ids)
    cfg = config or MasterConfig()
    core = MasterCore(cfg, likelihood=likelihood, body_metric=body_metric, store=None, gallery=gallery,
                      confidence_map=confidence_map)
    t_start = time.perf_counter()
    tracks: dict[int, TrackLog] = {}
    faces: dict[int, tuple[float, int]] = {}
    prev_assigned: dict[int, int] = {}
    rows_frame: list[int] = []
    rows_stamp: list[float] = []
    rows_gt: list[int] = []
    rows_track: list[int] = []
    rows_face: list[int] = []
    rows_name: list[int] = []
    rows_published: list[bool] = []
    name_index: dict[str, int] = {}
    rejected = 0

    def identity_changes(stamp: float) -> None:
        nonlocal prev_assigned
        raw = core.identity.assigned_tracks()  # tracker id -> face id; logged under the published ids
        internal = {core.public_id(tid): tid for tid in raw}
        assigned = {public: raw[tid] for public, tid in internal.items()}
        if assigned == prev_assigned:
            return
        for tid, fid in assigned.items():
            if prev_assigned.get(tid) == fid:
                continue
            kind = "known" if fid in faces else "new"
            if kind == "new":
                faces[fid] = (stamp, tid)
            log = tracks.get(tid)
            if log is None:  # a track decided at its split, before an association under its new id
                log = tracks[tid] = TrackLog(tid, stamp, stamp)
            inner = internal[tid]
            log.assignments.append((stamp, fid, kind))
            log.evidence.append(core.identity.evidence_of(inner) or "face")
            log.confidence.append(core.published_confidence(inner))  # identity_confidence of the decision
            log.released_s = None  # holding a face again (after a swap released the previous one)
        for tid in prev_assigned.keys() - assigned.keys():
            if tid in tracks:
                tracks[tid].released_s = stamp
        prev_assigned = assigned

    def sample(stamp: float) -> None:
        for rec in core.tracks():
            log = tracks.get(rec.track_id)
            if log is None:
                continue
            log.confirmed = True
            if rec.state == STATE_CONFIRMED:  # not the coasting prediction of a LOST track
                log.path.append((stamp, float(rec.position_xy[0]), float(rec.position_xy[1])))

    def mark_published(tids: set[int], stamp: float) -> None:
        """Set ``published_s`` of the frame's tracks that the master publishes now (the published list is asked
        only while one of them has not been published yet: once confirmed, a track is published until deleted)."""
        todo = {t for t in tids if t not in tracks or tracks[t].published_s is None}
        if not todo:
            return
        for rec in core.tracks():
            if rec.track_id in todo:
                log = tracks.get(rec.track_id)
                if log is None:
                    log = tracks[rec.track_id] = TrackLog(rec.track_id, stamp, stamp)
                log.published_s = stamp

    tick_index = math.floor(frames[0].stamp_s / tick_period_s) if frames else 0  # tick k at k * period

    def tick_until(stamp: float) -> None:
        nonlocal tick_index
        while (now := tick_index * tick_period_s) <= stamp:
            core.tick(now)
            identity_changes(now)
            sample(now)
            tick_index += 1

    n = len(frames)
    for i, frame in enumerate(frames):
        stamp = float(frame.stamp_s)
        tick_until(stamp)
        outcome = core.process_frame(frame)
        gt = np.asarray(frame_gt_ids[i]).tolist()
        if not outcome.accepted:
            rejected += 1
        identity_changes(stamp)
        track_of = outcome.track_of_person
        mark_published({core.public_id(inner) for inner in track_of.values()}, stamp)
        for j, person in enumerate(frame.people):
            inner = track_of.get(j, -1)
            tid = core.public_id(inner) if inner >= 0 else -1
            fid = 0
            shown = -1
            if tid >= 0:
                log = tracks.get(tid)
                if log is None:
                    log = tracks[tid] = TrackLog(tid, stamp, stamp)
                log.last_seen_s = stamp
                log.gt_counts[gt[j]] = log.gt_counts.get(gt[j], 0) + 1
                if person.embedding is not None:
                    log.face_detections += 1
                    log.face_gt.append((stamp, int(gt[j])))
                    if log.first_face_s is None:
                        log.first_face_s = stamp
                fid = core.published_face_id(inner)
                if fid:
                    name = core.face_name(fid)
                    if name:
                        shown = name_index.setdefault(name, len(name_index))
                        if name not in log.names:
                            log.names[name] = stamp
            rows_frame.append(i)
            rows_stamp.append(stamp)
            rows_gt.append(int(gt[j]))
            rows_track.append(int(tid))
            rows_face.append(int(fid))
            rows_name.append(shown)
            rows_published.append(tid >= 0 and tracks[tid].published_s is not None)
        if progress is not None and (i % 2000 == 0 or i == n - 1):
            progress(i + 1, n)
    if frames:  # let the last tracks time out, so that every track's end is recorded
        tcfg = cfg.tracker
        tick_until(float(frames[-1].stamp_s) + tcfg.lost_after_s + tcfg.delete_after_s + 2 * tick_period_s)
    return RunLog(
        method=cfg.method,
        tracks=tracks,
        faces=faces,
        det_frame=np.array(rows_frame, dtype=np.int64),
        det_stamp_s=np.array(rows_stamp, dtype=np.float64),
        det_gt=np.array(rows_gt, dtype=np.int64),
        det_track=np.array(rows_track, dtype=np.int64),
        det_face=np.array(rows_face, dtype=np.int64),
        n_frames=n,
        frames_rejected=rejected,
        days=tuple((int(d), float(a), float(b), tuple(int(g) for g in ids)) for d, a, b, ids in days),
        master_stats=core.stats.as_dict(),
        runtime_s=time.perf_counter() - t_start,
        det_name=np.array(rows_name, dtype=np.int64),
        names=tuple(name_index),
        body_metric=core.body_fused,
        decision_thresholds=decision_thresholds(cfg),
        det_published=np.array(rows_published, dtype=bool),
    )


def decision_thresholds(cfg: MasterConfig) -> dict[str, float]:
    """Evidence kind -> the posterior a decision must exceed under ``cfg`` (the threshold method votes: no face
    posterior threshold)."""
    out = {"body": float(cfg.body_posterior_threshold)}
    if cfg.method == "bayes":
        out["face"] = float(cfg.posterior_threshold)
    return out


def progress_to(stream: Any = sys.stderr, label: str = "frames") -> ProgressCallback:
    """A progress callback printing ``label done/total`` lines to ``stream``."""
    def report(done: int, total: int) -> None:
        print(f"  {label} {done}/{total}", file=stream, flush=True)
    return report
