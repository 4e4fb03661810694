"""Offline evaluation of the master core on a recorded scenario (Koide et al. 2017, Sec. V, Table II).

Two steps, both pure (no rclpy, no plotting):

1. :func:`run_master` feeds a scenario's camera frames, in stamp order, to a fresh :class:`MasterCore`
   (``core.tick`` at a regular period between frames, as the node's timer does) and records a
   :class:`RunLog`: for every detection its true person, track id, face id and name right after its
   frame; for every track its detections' true people, when it got which face id, the names it showed
   and its estimated path; for every face id the track that created it.
2. :func:`evaluate_run` turns a :class:`RunLog` (hand-made in tests) into the metrics: per-track
   re-identification outcomes (success / failure / none), re-identification time, recover rate,
   predefined-people names, and tracker- and identity-level IDF1 / MOTA / switches (``motmetrics``).

Every definition is written out in ``README.md, "What is counted, exactly"``; the docstrings below only summarise.
:func:`scenario_gallery` builds the predefined people of a scenario from photos it did not use.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.identity.likelihood import LikelihoodModel
from face_reid_master.records import STATE_CONFIRMED, CameraFrameRecord

__all__ = [
    "DEFAULT_TICK_PERIOD_S",
    "PURE_TRACK_MIN_PURITY",
    "GalleryInfo",
    "RunLog",
    "TrackLog",
    "TrackOutcome",
    "default_gallery_people",
    "evaluate_run",
    "evaluated_tracks",
    "face_persons",
    "mot_metrics",
    "progress_to",
    "run_master",
    "scenario_gallery",
    "track_outcomes",
]

DEFAULT_TICK_PERIOD_S = 0.2  # the node ticks at tick_rate_hz = 5 Hz
PURE_TRACK_MIN_PURITY = 0.95  # tracks at least this pure are "pure" (impure_tracks, pure_tracks diagnostics)
_MOT_METRICS = ("idf1", "idp", "idr", "mota", "num_switches", "num_fragmentations", "num_false_positives",
                "num_misses", "num_objects", "num_predictions", "mostly_tracked", "mostly_lost")

ProgressCallback = Callable[[int, int], None]


# ---------------------------------------------------------------------------------------------------
# Records of one run


@dataclass
class TrackLog:
    """What happened to one track (all stamps in scenario seconds).

    ``gt_counts``: true person (-1 = false positive) -> detections associated with the track.
    ``assignments``: (stamp, face id, "new" | "known") in order (Algorithm 1 assigns once per track; a
    later change would be listed too). ``names``: name -> first stamp it was shown on one of the
    track's detections. ``path``: (stamp, x, y) samples of the published estimate while CONFIRMED. ``face_gt``:
    (stamp, true person) of each detection with a face embedding.
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
    (0: none yet). ``faces``: face id -> (creation stamp, creating track id). ``days``: (day, start_s,
    end_s, gt ids) of the scenario (used to split cross-day re-identifications).
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

    def __post_init__(self) -> None:
        arrays = {k: getattr(self, k) for k in ("det_frame", "det_stamp_s", "det_gt", "det_track", "det_face")}
        sizes = {np.asarray(v).shape for v in arrays.values()}
        if len(sizes) != 1 or len(next(iter(sizes))) != 1:
            raise ValueError(f"RunLog detection arrays must be 1-D of one length, got shapes {sorted(sizes)}")
        for name, value in arrays.items():
            setattr(self, name, np.asarray(value, dtype=np.float64 if name == "det_stamp_s" else np.int64))
        if not np.all(np.isfinite(self.det_stamp_s)):
            raise ValueError("RunLog.det_stamp_s contains NaN or Inf")
        if self.det_frame.size > 1 and np.any(np.diff(self.det_frame) < 0):
            raise ValueError("RunLog detections must be in frame order")


# ---------------------------------------------------------------------------------------------------
# Running the master core


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
    core = MasterCore(cfg, likelihood=likelihood, store=None, gallery=gallery)
    t_start = time.perf_counter()
    tracks: dict[int, TrackLog] = {}
    faces: dict[int, tuple[float, int]] = {}
    prev_assigned: dict[int, int] = {}
    rows_frame: list[int] = []
    rows_stamp: list[float] = []
    rows_gt: list[int] = []
    rows_track: list[int] = []
    rows_face: list[int] = []
    rejected = 0

    def identity_changes(stamp: float) -> None:
        nonlocal prev_assigned
        assigned = core.identity.assigned_tracks()
        if assigned == prev_assigned:
            return
        for tid, fid in assigned.items():
            if prev_assigned.get(tid) == fid:
                continue
            kind = "known" if fid in faces else "new"
            if kind == "new":
                faces[fid] = (stamp, tid)
            log = tracks.get(tid)
            if log is None:  # identity of a track never seen in an association (cannot happen in the core)
                log = tracks[tid] = TrackLog(tid, stamp, stamp)
            log.assignments.append((stamp, fid, kind))
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
        for j, person in enumerate(frame.people):
            tid = track_of.get(j, -1)
            fid = 0
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
                fid = core.identity.face_id_of(tid) or 0
                if fid:
                    name = core.face_name(fid)
                    if name and name not in log.names:
                        log.names[name] = stamp
            rows_frame.append(i)
            rows_stamp.append(stamp)
            rows_gt.append(int(gt[j]))
            rows_track.append(int(tid))
            rows_face.append(int(fid))
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
    )


# ---------------------------------------------------------------------------------------------------
# Metrics


@dataclass(frozen=True)
class TrackOutcome:
    """The re-identification verdict of one evaluated track (see README.md, "What is counted, exactly")."""

    track_id: int
    person: int
    birth_s: float
    reid_case: bool  # a face of this person had been learned before the track's birth
    outcome: str  # "success" | "failure" | "none"
    failure_kind: str  # "" | "wrong_person" | "new_id" (known person given a new face id)
    face_id: int  # 0 when none
    decided_s: float | None
    cross_day: bool  # re-identification case whose person's previous track was on an earlier day
    face_busy: bool = False  # new id while every learned face of the person was held by another live track


def _day_of(stamp: float, days: Sequence[tuple[int, float, float, tuple[int, ...]]]) -> int:
    for day, start, end, _ in days:
        if start - 1e-9 <= stamp <= end + 1e-9:
            return day
    return 0


def evaluated_tracks(log: RunLog) -> list[TrackLog]:
    """Tracks that count: published at least once (confirmed) or given a face id, with a true person."""
    return [t for t in sorted(log.tracks.values(), key=lambda t: (t.birth_s, t.track_id))
            if (t.confirmed or t.assignments) and t.true_person >= 0]


def face_persons(log: RunLog) -> dict[int, int]:
    """Face id -> the true person it was learned from: the majority person of the face detections of the
    track that created it (NEW_FACE), which all went into that face; -1 if unknown."""
    return {fid: (log.tracks[tid].face_person if tid in log.tracks else -1) for fid, (_, tid) in log.faces.items()}


def track_outcomes(log: RunLog) -> list[TrackOutcome]:
    """Per evaluated track: is it a re-identification case, and did it get its person's face (docs)."""
    face_person = face_persons(log)
    learned_at: dict[int, float] = {}  # person -> first creation stamp of one of their faces
    for fid, (stamp, _) in log.faces.items():
        p = face_person[fid]
        if p >= 0:
            learned_at[p] = min(stamp, learned_at.get(p, math.inf))
    held: dict[int, list[tuple[float, float, int]]] = {}  # face id -> (from, until, track) holding intervals
    for t in log.tracks.values():
        for k, (stamp, fid, _) in enumerate(t.assignments):
            until = t.assignments[k + 1][0] if k + 1 < len(t.assignments) else (
                t.released_s if t.released_s is not None else math.inf)
            held.setdefault(fid, []).append((stamp, until, t.track_id))

    def all_faces_busy(person: int, at: float, track_id: int) -> bool:
        own = [f for f, (s, _) in log.faces.items() if face_person[f] == person and s < at]
        return bool(own) and all(any(a <= at < b and tid != track_id for a, b, tid in held.get(f, ())) for f in own)

    out: list[TrackOutcome] = []
    last_day_of_person: dict[int, int] = {}
    for t in evaluated_tracks(log):
        p = t.true_person
        reid = learned_at.get(p, math.inf) < t.birth_s
        first = t.first_assignment
        day = _day_of(t.birth_s, log.days)
        cross_day = reid and p in last_day_of_person and last_day_of_person[p] < day
        last_day_of_person[p] = day
        if first is None:
            out.append(TrackOutcome(t.track_id, p, t.birth_s, reid, "none", "", 0, None, cross_day))
            continue
        stamp, fid, kind = first
        if face_person.get(fid, -1) != p:
            verdict, why = "failure", "wrong_person"
        elif kind == "new" and reid:
            verdict, why = "failure", "new_id"
        else:
            verdict, why = "success", ""
        busy = why == "new_id" and all_faces_busy(p, stamp, t.track_id)
        out.append(TrackOutcome(t.track_id, p, t.birth_s, reid, verdict, why, fid, stamp, cross_day, busy))
    return out


def _mean(values: Sequence[float]) -> float | None:
    return round(float(np.mean(values)), 4) if len(values) else None


def _median(values: Sequence[float]) -> float | None:
    return round(float(np.median(values)), 4) if len(values) else None


def _ratio(num: int, den: int) -> float | None:
    return round(num / den, 4) if den else None


def paired_reid_times(log_a: RunLog, log_b: RunLog, names: tuple[str, str] = ("a", "b")) -> dict[str, Any]:
    """Re-identification times of two runs (e.g. bayes vs threshold) on the SAME tracks.

    The tracker does not depend on the face method, so track ids match between runs of one scenario.
    Compared: re-identification cases that both runs got right. Means over each run's own successes
    mix different tracks (one method may succeed on the hard ones), this does not.
    """
    def successes(log: RunLog) -> dict[int, TrackOutcome]:
        return {o.track_id: o for o in track_outcomes(log) if o.reid_case and o.outcome == "success"}

    a, b = successes(log_a), successes(log_b)
    common = sorted(set(a) & set(b))
    da = np.array([a[t].decided_s - a[t].birth_s for t in common], dtype=np.float64)  # type: ignore[operator]
    db = np.array([b[t].decided_s - b[t].birth_s for t in common], dtype=np.float64)  # type: ignore[operator]
    na, nb = names
    return {
        "tracks_both_successful": len(common),
        f"only_{na}_successful": len(set(a) - set(b)),
        f"only_{nb}_successful": len(set(b) - set(a)),
        f"mean_reid_time_{na}_s": _mean(da.tolist()),
        f"mean_reid_time_{nb}_s": _mean(db.tolist()),
        f"{na}_faster": int(np.count_nonzero(da < db - 1e-9)),
        f"{nb}_faster": int(np.count_nonzero(db < da - 1e-9)),
        "same_time": int(np.count_nonzero(np.abs(da - db) <= 1e-9)),
    }


def mot_metrics(log: RunLog, hypothesis: str = "track") -> dict[str, float | int]:
    """motmetrics over camera frames: GT = true people detected in the frame, hypotheses = the track
    ids (``hypothesis="track"``) or face ids (``"face"``) of the same detections, distance 0 between a
    detection's true person and its own hypothesis and no match otherwise (README.md, "What is counted, exactly")."""
    import motmetrics as mm

    if hypothesis not in ("track", "face"):
        raise ValueError(f"hypothesis must be 'track' or 'face', got {hypothesis!r}")
    hyp_all = log.det_track if hypothesis == "track" else log.det_face
    missing = -1 if hypothesis == "track" else 0
    acc = mm.MOTAccumulator(auto_id=False)
    frames = log.det_frame
    bounds = np.flatnonzero(np.diff(frames)) + 1
    starts = np.concatenate([[0], bounds]) if frames.size else np.zeros(0, dtype=np.int64)
    ends = np.concatenate([bounds, [frames.size]]) if frames.size else np.zeros(0, dtype=np.int64)
    for lo, hi in zip(starts.tolist(), ends.tolist(), strict=True):
        gts = log.det_gt[lo:hi].tolist()
        hyps = hyp_all[lo:hi].tolist()
        obj: list[int] = []
        obj_row: dict[int, int] = {}
        hyp: list[int] = []
        pairs: list[tuple[int, int]] = []
        for g, h in zip(gts, hyps, strict=True):
            row = -1
            if g >= 0 and g not in obj_row:  # a second detection of one person in a frame: hypothesis only
                row = obj_row[g] = len(obj)
                obj.append(g)
            if h != missing and h not in hyp:
                if row >= 0:
                    pairs.append((row, len(hyp)))
                hyp.append(h)
        if not obj and not hyp:
            continue
        dist = np.full((len(obj), len(hyp)), np.nan)
        for r, c in pairs:
            dist[r, c] = 0.0
        acc.update(obj, hyp, dist, frameid=int(frames[lo]))
    if not acc.events.shape[0]:
        return {k: 0 for k in _MOT_METRICS}
    summary = mm.metrics.create().compute(acc, metrics=list(_MOT_METRICS), name=hypothesis)
    out: dict[str, float | int] = {}
    for key in _MOT_METRICS:
        value = summary[key].iloc[0]
        out[key] = round(float(value), 4) if isinstance(value, float | np.floating) else int(value)
    return out


def evaluate_run(
    log: RunLog,
    *,
    gallery_people: Mapping[str, int] | None = None,
    scenario_summary: Mapping[str, Any] | None = None,
    with_mot: bool = True,
) -> dict[str, Any]:
    """All metrics of one run as a JSON-ready dict (definitions: README.md, "What is counted, exactly").

    ``gallery_people``: predefined name -> true person (gt id). ``scenario_summary``: the scenario's
    summary (``losses``, ``visible_segments``, ``per_day`` segments) for the tracker-side comparison.
    """
    outcomes = track_outcomes(log)
    by_id = {t.track_id: t for t in log.tracks.values()}
    reid = [o for o in outcomes if o.reid_case]
    first = [o for o in outcomes if not o.reid_case]
    n_success = sum(o.outcome == "success" for o in reid)
    fail_wrong = sum(o.failure_kind == "wrong_person" for o in reid)
    fail_new = sum(o.failure_kind == "new_id" for o in reid)
    none = sum(o.outcome == "none" for o in reid)
    times = [o.decided_s - o.birth_s for o in reid if o.outcome == "success" and o.decided_s is not None]
    times_face = []
    for o in reid:
        first_face = by_id[o.track_id].first_face_s
        if o.outcome == "success" and o.decided_s is not None and first_face is not None:
            times_face.append(o.decided_s - first_face)
    first_ok = [o for o in first if o.outcome == "success"]
    first_wrong = sum(o.outcome == "failure" for o in first)
    first_times = [o.decided_s - o.birth_s for o in first if o.decided_s is not None]
    all_decided = [o.decided_s - o.birth_s for o in outcomes if o.decided_s is not None]
    summary = dict(scenario_summary or {})
    gt_losses = summary.get("losses")
    day_people = [set(d[3]) for d in sorted(log.days)]
    returning = sum(len(day_people[k] & set().union(*day_people[:k])) for k in range(1, len(day_people)))
    gt_opportunities = int(gt_losses) + returning if gt_losses is not None else None
    cross = [o for o in reid if o.cross_day]

    reidentification = {
        "tracks": len(reid),
        "success": n_success,
        "failure": fail_wrong + fail_new,
        "failure_wrong_person": fail_wrong,
        "failure_new_id": fail_new,
        "failure_new_id_face_busy": sum(o.face_busy for o in reid),
        "none": none,
        "mean_reid_time_s": _mean(times),
        "median_reid_time_s": _median(times),
        "mean_reid_time_from_first_face_s": _mean(times_face),
        "recover_rate": _ratio(n_success, len(reid)),
        "recover_rate_all_tracks": _ratio(n_success, len(outcomes)),
        "recover_rate_gt_opportunities": _ratio(n_success, gt_opportunities) if gt_opportunities else None,
        "gt_reid_opportunities": gt_opportunities,
        "cross_day": {
            "tracks": len(cross),
            "success": sum(o.outcome == "success" for o in cross),
            "failure": sum(o.outcome == "failure" for o in cross),
            "none": sum(o.outcome == "none" for o in cross),
        },
    }
    first_appearance = {
        "tracks": len(first),
        "new_id": sum(o.outcome == "success" and by_id[o.track_id].first_assignment is not None
                      and by_id[o.track_id].assignments[0][2] == "new" for o in first),
        "success": len(first_ok),
        "failure_wrong_person": first_wrong,
        "none": sum(o.outcome == "none" for o in first),
        "mean_decision_time_s": _mean(first_times),
    }
    pure = [o for o in outcomes if by_id[o.track_id].purity >= PURE_TRACK_MIN_PURITY]
    pure_reid = [o for o in pure if o.reid_case]
    pure_tracks = {  # the identity layer alone: tracks the tracker kept on one person
        "min_purity": PURE_TRACK_MIN_PURITY,
        "tracks": len(pure),
        "reid_tracks": len(pure_reid),
        "reid_success": sum(o.outcome == "success" for o in pure_reid),
        "reid_failure": sum(o.outcome == "failure" for o in pure_reid),
        "reid_none": sum(o.outcome == "none" for o in pure_reid),
        "first_appearance_failure": sum(o.outcome == "failure" for o in pure if not o.reid_case),
        "mean_reid_time_s": _mean([o.decided_s - o.birth_s for o in pure_reid
                                   if o.outcome == "success" and o.decided_s is not None]),
    }
    table_ii = {
        "success": n_success,
        "failure": fail_wrong + fail_new + first_wrong,
        "re_id_time_s": _mean(times),
        "recover_rate": reidentification["recover_rate"],
        "recover_rate_paper": reidentification["recover_rate_gt_opportunities"],
    }

    evaluated = evaluated_tracks(log)
    fp_tracks = [t for t in log.tracks.values() if (t.confirmed or t.assignments) and t.true_person < 0]
    per_person: dict[int, int] = Counter(t.true_person for t in evaluated)
    gt_segments: dict[int, int] = {}
    for day in summary.get("per_day", []) or []:
        for gt, segs in (day.get("segments") or {}).items():
            gt_segments[int(gt)] = gt_segments.get(int(gt), 0) + len(segs)
    days_present: dict[int, int] = Counter(g for d in log.days for g in d[3])
    tracker_losses = sum(max(0, n - days_present.get(p, 1)) for p, n in per_person.items())
    persons = sorted(set(per_person) | set(gt_segments))
    tracker = {
        "tracks_created": len(log.tracks),
        "tracks_evaluated": len(evaluated),
        "tracks_never_confirmed": sum(not t.confirmed and not t.assignments for t in log.tracks.values()),
        "false_positive_tracks": len(fp_tracks),
        "impure_tracks": sum(t.purity < PURE_TRACK_MIN_PURITY for t in evaluated),
        "mean_purity": _mean([t.purity for t in evaluated]),
        "tracker_losses": tracker_losses,
        "gt_losses": gt_losses,
        "gt_visible_segments": summary.get("visible_segments"),
        "tracks_per_person": {str(p): per_person.get(p, 0) for p in persons},
        "gt_segments_per_person": {str(p): gt_segments[p] for p in persons if p in gt_segments},
    }

    face_person = face_persons(log)
    faces_of: dict[int, int] = Counter(p for p in face_person.values())
    people_seen = {t.true_person for t in evaluated}
    faces_info = {
        "created": len(log.faces),
        "people_with_a_face": sum(1 for p in people_seen if faces_of.get(p, 0) > 0),
        "people_with_several_faces": sum(1 for p in people_seen if faces_of.get(p, 0) > 1),
        "people_seen": len(people_seen),
        "faces_of_no_person": faces_of.get(-1, 0),
        "faces_learned_from_another_person_than_their_track": sum(
            face_person[f] != log.tracks[tid].true_person for f, (_, tid) in log.faces.items() if tid in log.tracks),
    }

    result: dict[str, Any] = {
        "method": log.method,
        "table_ii": table_ii,
        "reidentification": reidentification,
        "first_appearance": first_appearance,
        "pure_tracks": pure_tracks,
        "decision_time_all_s": _mean(all_decided),
        "tracker": tracker,
        "faces": faces_info,
        "predefined_people": _names(evaluated, gallery_people),
        "frames": log.n_frames,
        "frames_rejected": log.frames_rejected,
        "detections": int(log.det_gt.size),
        "master_stats": dict(log.master_stats),
        "run_time_s": round(log.runtime_s, 2),
    }
    if with_mot:
        t0 = time.perf_counter()
        result["mot"] = {"tracker": mot_metrics(log, "track"), "identity": mot_metrics(log, "face")}
        result["mot_time_s"] = round(time.perf_counter() - t0, 2)
    return result


def _names(evaluated: Sequence[TrackLog], gallery_people: Mapping[str, int] | None) -> dict[str, Any]:
    """Predefined-people outcome per track: right / wrong / no name (README.md, "What is counted, exactly")."""
    if not gallery_people:
        return {"gallery_people": 0}
    person_name = {gt: name for name, gt in gallery_people.items()}
    right = wrong = no_name = other_named = other_tracks = 0
    times: list[float] = []
    for t in evaluated:
        p = t.true_person
        if p in person_name:
            if any(name != person_name[p] for name in t.names):
                wrong += 1
            elif person_name[p] in t.names:
                right += 1
                times.append(t.names[person_name[p]] - t.birth_s)
            else:
                no_name += 1
        else:
            other_tracks += 1
            other_named += bool(t.names)
    return {
        "gallery_people": len(gallery_people),
        "gallery_tracks": right + wrong + no_name,
        "right_name": right,
        "wrong_name": wrong,
        "no_name": no_name,
        "mean_time_to_name_s": _mean(times),
        "other_tracks": other_tracks,
        "other_tracks_named": other_named,
    }


# ---------------------------------------------------------------------------------------------------
# Predefined people of a scenario


@dataclass
class GalleryInfo:
    """Predefined people built for a scenario: embeddings per name, their true person, photo sources."""

    people: dict[str, NDArray[np.float32]]
    gt_of_name: dict[str, int]
    photos: dict[str, int]  # name -> gallery photos embedded
    from_scenario_photo: list[str]  # names whose gallery had to reuse a photo the scenario used
    skipped: str = ""  # why no gallery was built (empty when built)

    def as_json(self) -> dict[str, Any]:
        if self.skipped:
            return {"skipped": self.skipped}
        return {"people": {n: {"gt_id": self.gt_of_name[n], "photos": self.photos[n]} for n in sorted(self.people)},
                "reused_a_scenario_photo": sorted(self.from_scenario_photo)}


def default_gallery_people(document: Mapping[str, Any], count: int | None = None) -> list[int]:
    """``count`` (default: half, rounded down) of the day-1 people, chosen by a permutation seeded with the
    scenario seed, sorted by gt id."""
    days = sorted(document.get("days", []), key=lambda d: d["day"])
    day1 = sorted(int(g) for g in days[0]["gt_ids"]) if days else []
    k = len(day1) // 2 if count is None else int(count)
    if not 0 <= k <= len(day1):
        raise ValueError(f"gallery people must be within [0, {len(day1)}] (day-1 people), got {k}")
    order = np.random.default_rng([int(document.get("seed", 0)), 4]).permutation(len(day1))
    return sorted(day1[int(i)] for i in order[:k])


def _resolve_faces_dir(document: Mapping[str, Any], scenario_dir: Path, faces_dir: str | Path | None) -> Path | None:
    candidates = [Path(faces_dir)] if faces_dir is not None else []
    recorded = document.get("faces_dir")
    if recorded:
        candidates += [Path(recorded), scenario_dir / recorded]
    for c in candidates:
        if c.is_dir():
            return c
    return None


def scenario_gallery(
    document: Mapping[str, Any],
    scenario_dir: str | Path,
    gt_ids: Sequence[int],
    *,
    faces_dir: str | Path | None = None,
    embedder: Any | None = None,
    log: Any | None = None,
) -> GalleryInfo:
    """Predefined people for ``gt_ids``: each identity's photos in its faces folder that the scenario did
    NOT use on any day, embedded with the real models (``PhotoEmbedder``). If none is usable, one photo
    the scenario used is taken (and listed in ``from_scenario_photo``). A missing faces folder gives a
    GalleryInfo with ``skipped`` set (the evaluation then has no names)."""
    if not gt_ids:
        return GalleryInfo({}, {}, {}, [], skipped="no gallery people requested")
    base = _resolve_faces_dir(document, Path(scenario_dir), faces_dir)
    if base is None:
        return GalleryInfo({}, {}, {}, [], skipped=f"faces folder {document.get('faces_dir')!r} not found "
                                                   "(pass --faces)")
    from face_reid_camera.faces.photos import IMAGE_SUFFIXES, PhotoEmbedder, PhotoError

    emb = embedder if embedder is not None else PhotoEmbedder()
    photo_path = {int(p["index"]): str(p["path"]) for p in document.get("photos", [])}
    idents = {int(i["gt_id"]): i for i in document.get("identities", [])}
    info = GalleryInfo({}, {}, {}, [])
    for gt in gt_ids:
        ident = idents.get(int(gt))
        if ident is None:
            raise ValueError(f"gt id {gt} is not an identity of the scenario")
        name = str(ident["name"])
        used = {photo_path[i] for day_list in ident.get("photos", {}).values() for i in day_list if i in photo_path}
        folder = base / name
        files = sorted(f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES) \
            if folder.is_dir() else []
        rows = []
        for f in files:
            if f.relative_to(base).as_posix() in used:
                continue
            try:
                e = emb.embed_photo(f)
            except PhotoError:
                continue
            if e is not None:
                rows.append(e.embedding)
        if not rows:
            for rel in sorted(used):
                try:
                    e = emb.embed_photo(base / rel)
                except PhotoError:
                    continue
                if e is not None:
                    rows.append(e.embedding)
                    info.from_scenario_photo.append(name)
                    if log is not None:
                        print(f"gallery: {name} has no unused photo; reusing scenario photo {rel}", file=log)
                    break
        if not rows:
            raise ValueError(f"no usable gallery photo for {name} in {folder}")
        info.people[name] = np.stack(rows).astype(np.float32)
        info.gt_of_name[name] = int(gt)
        info.photos[name] = len(rows)
    return info


def progress_to(stream: Any = sys.stderr, label: str = "frames") -> ProgressCallback:
    """A progress callback printing ``label done/total`` lines to ``stream``."""
    def report(done: int, total: int) -> None:
        print(f"  {label} {done}/{total}", file=stream, flush=True)
    return report
