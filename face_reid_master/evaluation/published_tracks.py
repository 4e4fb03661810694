"""What the master published on /tracks_named, judged against the ground truth (demo, live evaluation).

A live run has no detection-level truth: each confirmed track of each message is attributed to the nearest
true person in the room (within :data:`MATCH_RADIUS_M`), a track's person is its majority, and the result is
a :class:`~face_reid_master.evaluation.runner.RunLog` whose "detections" are these published samples, so that
:func:`~face_reid_master.evaluation.metrics.evaluate_run` computes the same metrics as offline. Pure: no rclpy (the
message conversion only reads fields).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_master.evaluation.runner import RunLog, TrackLog
from face_reid_master.records import STATE_CONFIRMED, NamedTrackRecord

__all__ = ["MATCH_RADIUS_M", "TrackMessage", "TruthLookup", "nearest_person", "run_log_from_messages"]

MATCH_RADIUS_M = 1.0  # a track is at a true person when within this distance

# true positions at scene times: (T,) -> ((T, P, 2) xy, (T, P) in-room flags); person index = gt id
TruthLookup = Callable[[NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.bool_]]]


@dataclass(frozen=True)
class TrackMessage:
    """One /tracks_named message: its stamp (scene seconds) and the tracks."""

    stamp_s: float
    tracks: tuple[NamedTrackRecord, ...]


def nearest_person(xy: NDArray[np.float64], true_xy: NDArray[np.float64], inside: NDArray[np.bool_]) -> int:
    """Index of the in-room true person nearest to ``xy`` within the match radius, -1 if none."""
    if not inside.any():
        return -1
    d = np.where(inside, np.linalg.norm(true_xy - xy[None, :], axis=1), np.inf)
    k = int(np.argmin(d))
    return k if d[k] <= MATCH_RADIUS_M else -1


def run_log_from_messages(messages: Sequence[TrackMessage], truth: TruthLookup, num_people: int,
                          days: Sequence[tuple[int, float, float, Sequence[int]]], method: str = "bayes") -> RunLog:
    """A :class:`~face_reid_master.evaluation.runner.RunLog` from the published tracks: each confirmed track in each
    message is a sample attributed to the nearest true person (the track's person is the majority); face
    ids and names are taken as published (a face id first shown on a track is "new", later "known")."""
    tracks: dict[int, TrackLog] = {}
    faces: dict[int, tuple[float, int]] = {}
    current_face: dict[int, int] = {}
    rows: list[tuple[int, float, int, int, int]] = []
    msgs = sorted(messages, key=lambda m: m.stamp_s)
    stamps = np.array([m.stamp_s for m in msgs], dtype=np.float64)
    true_xy, inside = truth(stamps) if msgs else (np.zeros((0, num_people, 2)), None)
    for i, msg in enumerate(msgs):
        present = set()
        for tr in msg.tracks:
            tid = int(tr.track_id)
            present.add(tid)
            log = tracks.get(tid)
            if log is None:
                birth = tr.first_seen_s if math.isfinite(tr.first_seen_s) and tr.first_seen_s > -1e6 else msg.stamp_s
                log = tracks[tid] = TrackLog(tid, min(birth, msg.stamp_s), msg.stamp_s, confirmed=True)
            log.last_seen_s = max(log.last_seen_s, tr.last_seen_s)
            log.face_detections = max(log.face_detections, int(tr.face_observations))
            if tr.face_observations > 0 and log.first_face_s is None:
                log.first_face_s = msg.stamp_s
            fid = int(tr.face_id)
            if fid and current_face.get(tid) != fid:
                kind = "known" if fid in faces else "new"
                faces.setdefault(fid, (msg.stamp_s, tid))
                log.assignments.append((msg.stamp_s, fid, kind))
                log.evidence.append("body" if tr.identity_evidence == "body" else "face")  # what decided it
                log.confidence.append(float(tr.identity_confidence))  # published with the new face id
            elif not fid and current_face.get(tid):
                log.released_s = msg.stamp_s
            current_face[tid] = fid
            if fid and tr.name and tr.name not in log.names:
                log.names[tr.name] = msg.stamp_s
            if tr.state == STATE_CONFIRMED and inside is not None:
                gt = nearest_person(np.asarray(tr.position_xy, dtype=np.float64), true_xy[i], inside[i])
                log.gt_counts[gt] = log.gt_counts.get(gt, 0) + 1
                log.path.append((msg.stamp_s, float(tr.position_xy[0]), float(tr.position_xy[1])))
                rows.append((i, msg.stamp_s, gt, tid, fid))
        for tid, fid in list(current_face.items()):
            if tid not in present:
                if fid and tracks[tid].released_s is None:
                    tracks[tid].released_s = msg.stamp_s
                del current_face[tid]
    cols = list(zip(*rows, strict=True)) if rows else [(), (), (), (), ()]
    return RunLog(
        method=method, tracks=tracks, faces=faces,
        det_frame=np.array(cols[0], dtype=np.int64), det_stamp_s=np.array(cols[1], dtype=np.float64),
        det_gt=np.array(cols[2], dtype=np.int64), det_track=np.array(cols[3], dtype=np.int64),
        det_face=np.array(cols[4], dtype=np.int64), n_frames=len(msgs),
        days=tuple((int(d), float(a), float(b), tuple(int(g) for g in ids)) for d, a, b, ids in days),
    )
