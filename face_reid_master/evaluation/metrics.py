"""The evaluation's metrics of a :class:`~face_reid_master.evaluation.runner.RunLog` (Koide et al. 2017, Sec. V,
Table II): per-track re-identification outcomes (success / failure / none), re-identification time, recover
rate, predefined-people names, tracker- and identity-level IDF1 / MOTA / switches (``motmetrics``).

Every definition is written out in ``docs/evaluation.md, "What is counted"``; the docstrings only summarise.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.evaluation.runner import RunLog, TrackLog

__all__ = [
    "PURE_TRACK_MIN_PURITY",
    "REID_MIN_FACE_DETECTIONS",
    "TrackOutcome",
    "decision_verdict",
    "evaluate_run",
    "evaluated_tracks",
    "face_persons",
    "identity_per_detection",
    "learned_at",
    "mot_metrics",
    "paired_reid_times",
    "reid_with_face",
    "track_outcomes",
]

PURE_TRACK_MIN_PURITY = 0.95  # tracks at least this pure are "pure" (impure_tracks, pure_tracks diagnostics)
REID_MIN_FACE_DETECTIONS = 3  # a re-identification case "showed a face" with at least this many face detections
_MOT_METRICS = ("idf1", "idp", "idr", "mota", "num_switches", "num_fragmentations", "num_false_positives",
                "num_misses", "num_objects", "num_predictions", "mostly_tracked", "mostly_lost")


@dataclass(frozen=True)
class TrackOutcome:
    """The re-identification verdict of one evaluated track (see docs/evaluation.md, "What is counted")."""

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
    evidence: str = ""  # what decided it: "face" or "body" ("" = undecided)
    after_switch: bool = False  # wrong person, but the one the track followed from its decision to its end


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
    """Face id -> the true person it was learned from: the majority person of the face detections the
    track that created it (NEW_FACE) had at that moment (its buffer became the face); -1 if unknown."""
    return {fid: (log.tracks[tid].face_person_until(stamp) if tid in log.tracks else -1)
            for fid, (stamp, tid) in log.faces.items()}


def holding_intervals(log: RunLog) -> dict[int, list[tuple[float, float, int]]]:
    """Face id -> (from, until, track id) of every time a track held the face (until: inf while held)."""
    held: dict[int, list[tuple[float, float, int]]] = {}
    for t in log.tracks.values():
        for k, (stamp, fid, _) in enumerate(t.assignments):
            until = t.assignments[k + 1][0] if k + 1 < len(t.assignments) else (
                t.released_s if t.released_s is not None else math.inf)
            held.setdefault(fid, []).append((stamp, until, t.track_id))
    return held


def learned_at(log: RunLog, face_person: Mapping[int, int]) -> dict[int, float]:
    """Person -> creation stamp of their first learned face (``face_person``: :func:`face_persons`)."""
    out: dict[int, float] = {}
    for fid, (stamp, _) in log.faces.items():
        p = face_person[fid]
        if p >= 0:
            out[p] = min(stamp, out.get(p, math.inf))
    return out


def decision_verdict(face_person: int, kind: str, person: int, reid_case: bool) -> tuple[str, str]:
    """("success" | "failure", "" | "wrong_person" | "new_id") of giving ``person`` a face learned from
    ``face_person``, ``kind`` "new" or "known"; a re-identification case must get a known face (docs)."""
    if face_person != person:
        return "failure", "wrong_person"
    if kind == "new" and reid_case:
        return "failure", "new_id"
    return "success", ""


def track_outcomes(log: RunLog) -> list[TrackOutcome]:
    """Per evaluated track: is it a re-identification case, and did it get its person's face (docs)."""
    face_person = face_persons(log)
    learned = learned_at(log, face_person)
    held = holding_intervals(log)

    def all_faces_busy(person: int, at: float, track_id: int) -> bool:
        own = [f for f, (s, _) in log.faces.items() if face_person[f] == person and s < at]
        return bool(own) and all(any(a <= at < b and tid != track_id for a, b, tid in held.get(f, ())) for f in own)

    followed_from = _followed_from(log)
    out: list[TrackOutcome] = []
    last_day_of_person: dict[int, int] = {}
    for t in evaluated_tracks(log):
        p = t.true_person
        reid = learned.get(p, math.inf) < t.birth_s
        first = t.first_assignment
        day = _day_of(t.birth_s, log.days)
        cross_day = reid and p in last_day_of_person and last_day_of_person[p] < day
        last_day_of_person[p] = day
        if first is None:
            out.append(TrackOutcome(t.track_id, p, t.birth_s, reid, "none", "", 0, None, cross_day))
            continue
        stamp, fid, kind = first
        verdict, why = decision_verdict(face_person.get(fid, -1), kind, p, reid)
        busy = why == "new_id" and all_faces_busy(p, stamp, t.track_id)
        evidence = t.evidence[0] if t.evidence else "face"
        switched = why == "wrong_person" and followed_from(t.track_id, stamp, face_person.get(fid, -1))
        out.append(TrackOutcome(t.track_id, p, t.birth_s, reid, verdict, why, fid, stamp, cross_day, busy,
                                evidence, switched))
    return out


def _followed_from(log: RunLog) -> Callable[[int, float, int], bool]:
    """A test: did a track follow ``person`` from ``stamp`` to its end (at least ``PURE_TRACK_MIN_PURITY`` of its
    true people's detections from then on)? False without per-detection records (a live run)."""
    order = np.argsort(log.det_track, kind="stable")
    by_track = log.det_track[order]

    def followed(track_id: int, stamp: float, person: int) -> bool:
        lo, hi = np.searchsorted(by_track, [track_id, track_id + 1])
        rows = order[lo:hi]
        gt = log.det_gt[rows][log.det_stamp_s[rows] >= stamp]
        gt = gt[gt >= 0]
        return bool(gt.size) and float(np.mean(gt == person)) >= PURE_TRACK_MIN_PURITY

    return followed


def reid_with_face(outcomes: Sequence[TrackOutcome], tracks: Mapping[int, TrackLog],
                   min_faces: int = REID_MIN_FACE_DETECTIONS) -> dict[str, Any]:
    """The re-identification cases whose track had at least ``min_faces`` face detections, and how many were
    recovered right: the recover rate a perfect identity logic could reach (docs/evaluation.md)."""
    cases = [o for o in outcomes if o.reid_case and tracks[o.track_id].face_detections >= min_faces]
    success = sum(o.outcome == "success" for o in cases)
    return {
        "min_face_detections": min_faces,
        "tracks": len(cases),
        "success": success,
        "failure": sum(o.outcome == "failure" for o in cases),
        "none": sum(o.outcome == "none" for o in cases),
        "recover_rate": _ratio(success, len(cases)),
    }


def identity_per_detection(log: RunLog, face_person: Mapping[int, int]) -> dict[str, Any]:
    """What a robot reads per detection: of the true people's detections on a published track, the share shown
    another person's face id (``face_person``: a face id's person, :func:`face_persons`) and the share shown no
    face id yet (docs/evaluation.md, "What is counted")."""
    counted = (log.det_track >= 0) & (log.det_gt >= 0)
    if log.det_published.size:
        counted &= log.det_published
    fid = log.det_face[counted]
    gt = log.det_gt[counted]
    owner = np.array([face_person.get(int(f), -1) for f in fid.tolist()], dtype=np.int64)
    decided = fid > 0
    right = int(np.count_nonzero(decided & (owner == gt)))
    wrong_rows = decided & (owner != gt)
    wrong = int(np.count_nonzero(wrong_rows))
    undecided = int(np.count_nonzero(~decided))
    n = int(fid.size)
    carried = _carried(log.det_track[counted], log.det_stamp_s[counted], gt, owner, wrong_rows)
    return {
        "published_detections": n,
        "right": right,
        "wrong_identity": wrong,
        "wrong_identity_carried": carried,
        "undecided": undecided,
        "right_rate": _ratio(right, n),
        "wrong_identity_rate": _ratio(wrong, n),
        "wrong_identity_carried_rate": _ratio(carried, n),
        "undecided_rate": _ratio(undecided, n),
        "wrong_of_decided_rate": _ratio(wrong, right + wrong),
    }


def _carried(track: NDArray[np.int64], stamp: NDArray[np.float64], gt: NDArray[np.int64], owner: NDArray[np.int64],
             wrong: NDArray[np.bool_]) -> int:
    """How many of the ``wrong`` detections show the face id of a person their track followed earlier: an identity
    the tracker carried onto someone else (the counted detections' track, stamp, true person and shown id's person)."""
    carried = 0
    for t in np.unique(track[wrong]).tolist():
        mine = track == t
        seen: dict[int, float] = {}  # person -> the track's first detection of them
        for p, s in zip(gt[mine].tolist(), stamp[mine].tolist(), strict=True):
            seen[p] = min(seen.get(p, math.inf), s)
        rows = np.flatnonzero(mine & wrong)
        carried += int(sum(seen.get(int(owner[i]), math.inf) < stamp[i] for i in rows.tolist()))
    return carried


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
    detection's true person and its own hypothesis and no match otherwise (docs/evaluation.md, "What is counted")."""
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
    """All metrics of one run as a JSON-ready dict (definitions: docs/evaluation.md, "What is counted").

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
        "failure_wrong_person_after_switch": sum(o.after_switch for o in reid),
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
            "decided_by_body": sum(o.evidence == "body" for o in cross),
        },
        "with_face": reid_with_face(outcomes, by_id),
        "by_evidence": {e: {"success": sum(o.outcome == "success" and o.evidence == e for o in reid),
                            "failure": sum(o.outcome == "failure" and o.evidence == e for o in reid)}
                        for e in ("face", "body")},
    }
    first_appearance = {
        "tracks": len(first),
        "new_id": sum(o.outcome == "success" and by_id[o.track_id].first_assignment is not None
                      and by_id[o.track_id].assignments[0][2] == "new" for o in first),
        "success": len(first_ok),
        "failure_wrong_person": first_wrong,
        "failure_wrong_person_after_switch": sum(o.after_switch for o in first),
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
        "reid_failure_wrong_person": sum(o.failure_kind == "wrong_person" for o in pure_reid),
        "reid_none": sum(o.outcome == "none" for o in pure_reid),
        "first_appearance_failure": sum(o.outcome == "failure" for o in pure if not o.reid_case),
        "mean_reid_time_s": _mean([o.decided_s - o.birth_s for o in pure_reid
                                   if o.outcome == "success" and o.decided_s is not None]),
    }
    table_ii = {
        "success": n_success,
        "failure": fail_wrong + fail_new + first_wrong,
        "failure_after_switch": sum(o.after_switch for o in outcomes),
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
        "predefined_people": {
            **_names(evaluated, gallery_people),
            "pure_tracks": _names([t for t in evaluated if t.purity >= PURE_TRACK_MIN_PURITY], gallery_people),
            "detections": _names_per_detection(log, gallery_people),
        },
        "per_detection": identity_per_detection(log, face_persons(log)),
        "frames": log.n_frames,
        "frames_rejected": log.frames_rejected,
        "detections": int(log.det_gt.size),
        "master_stats": dict(log.master_stats),
        "run_time_s": round(log.runtime_s, 2),
    }
    from face_reid_master.evaluation.calibration import calibration_report, run_decisions  # imports this module

    result["calibration"] = calibration_report(run_decisions(log), thresholds=log.decision_thresholds,
                                               reid_tracks=len(reid))
    if with_mot:
        t0 = time.perf_counter()
        result["mot"] = {"tracker": mot_metrics(log, "track"), "identity": mot_metrics(log, "face")}
        result["mot_time_s"] = round(time.perf_counter() - t0, 2)
    return result


def _names_per_detection(log: RunLog, gallery_people: Mapping[str, int] | None) -> dict[str, Any]:
    """Names shown on tracked detections, judged by each detection's own true person (docs/evaluation.md,
    "What is counted"): unlike the per-track counts, a track the tracker swapped is right before the swap."""
    if not gallery_people or not log.det_name.size:
        return {}
    tracked = (log.det_track >= 0) & (log.det_gt >= 0)
    # true person of each shown name (-2: not a gallery name); the last entry is det_name -1: no name
    name_gt = np.array([gallery_people.get(n, -2) for n in log.names] + [-1], dtype=np.int64)
    shown = name_gt[log.det_name]
    in_gallery = np.isin(log.det_gt, np.fromiter(gallery_people.values(), dtype=np.int64)) & tracked
    others = tracked & ~in_gallery
    right = int(np.count_nonzero(in_gallery & (shown == log.det_gt)))
    wrong = int(np.count_nonzero(in_gallery & (shown != -1) & (shown != log.det_gt)))
    n_gallery, n_others = int(in_gallery.sum()), int(others.sum())
    named_others = int(np.count_nonzero(others & (shown != -1)))
    return {
        "gallery_detections": n_gallery,
        "right_name": right,
        "wrong_name": wrong,
        "wrong_name_rate": _ratio(wrong, n_gallery),
        "other_detections": n_others,
        "other_named": named_others,
        "other_named_rate": _ratio(named_others, n_others),
    }


def _names(evaluated: Sequence[TrackLog], gallery_people: Mapping[str, int] | None) -> dict[str, Any]:
    """Predefined-people outcome per track: right / wrong / no name (docs/evaluation.md, "What is counted")."""
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
