"""Helpers shared by the tracker tests of this folder."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from trajectories import SyntheticFrame, person_reports

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import Detection, TrackSnapshot, UpdateResult
from face_reid_master.tracking.tracker import Tracker


def run(
    frames: Sequence[SyntheticFrame], config: TrackerConfig | None = None
) -> tuple[Tracker, list[UpdateResult]]:
    tracker = Tracker(config)
    return tracker, [tracker.update(f.detections, f.stamp_s, f.camera_id) for f in frames]


def det(x: float, y: float, std: float = 0.05, height_m: float = float("nan")) -> Detection:
    return Detection(np.array([x, y]), std, height_m)


def snap(tracker: Tracker, track_id: int) -> TrackSnapshot:
    (s,) = [s for s in tracker.snapshots() if s.track_id == track_id]
    return s


def assert_one_track_per_person(frames: Sequence[SyntheticFrame], results: Sequence[UpdateResult]) -> None:
    reports = person_reports(frames, results)
    assert reports, "no person was tracked"
    for pid, rep in reports.items():
        assert rep.switches == 0, f"person {pid} switched track: {rep.track_sequence}"
        assert rep.dominant_fraction >= 0.95, f"person {pid}: only {rep.dominant_fraction:.2f} on one track"
        assert rep.first_track == rep.last_track == rep.dominant_track
    dominant = [rep.dominant_track for rep in reports.values()]
    assert len(set(dominant)) == len(dominant), f"two people share a track: {dominant}"


def straight_frames(
    stamps: Sequence[float], cams: Sequence[str] | None = None
) -> list[tuple[float, str, list[Detection]]]:
    cams = cams or ["cam"] * len(stamps)
    rng = np.random.default_rng(7)
    out = []
    for t, c in zip(stamps, cams, strict=True):
        xy = np.array([1.0 * t, 0.5 * t]) + rng.normal(scale=0.03, size=2)
        out.append((t, c, [Detection(xy, 0.05)]))
    return out
