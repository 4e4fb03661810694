"""Track lifecycle (tracking.lifecycle): confirm, lose, recover, merge duplicates, expire, births."""

from __future__ import annotations

import math

import pytest
from tracking_test_helpers import det, run, snap
from trajectories import (
    CameraFov,
    Scenario,
    Walker,
    person_reports,
)

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import FrameStatus, TrackState, UpdateResult
from face_reid_master.tracking.tracker import Tracker

LIFECYCLE = TrackerConfig(detections_to_confirm=3, confirm_window_s=1.0, lost_after_s=1.0, delete_after_s=2.0)


def test_lifecycle_transitions_at_exact_times() -> None:
    tracker = Tracker(LIFECYCLE)
    events: dict[float, UpdateResult] = {}
    for t in (0.0, 0.25, 0.5):  # three hits within the window -> confirmed on the third
        events[t] = tracker.update([det(0.0, 0.0)], t, "cam")
    assert events[0.0].created == (1,) and snap(tracker, 1).hits == 3
    assert events[0.25].confirmed == () and events[0.5].confirmed == (1,)
    states = {}
    for k in range(3, 17):  # empty frames every 0.25 s up to t = 4.0
        t = k * 0.25
        events[t] = tracker.update([], t, "cam")
        states[t] = snap(tracker, 1).state if 1 in tracker.track_ids() else TrackState.DELETED
    assert states[1.25] is TrackState.CONFIRMED
    assert events[1.5].lost == (1,) and states[1.5] is TrackState.LOST  # 1.0 s after last detection
    assert states[3.25] is TrackState.LOST and events[3.25].deleted == ()
    assert events[3.5].deleted == (1,) and states[3.5] is TrackState.DELETED  # + 2.0 s lost
    assert tracker.num_tracks == 0 and tracker.stats.tracks_deleted == 1


def test_tentative_track_not_confirmed_in_its_window_is_deleted() -> None:
    tracker = Tracker(LIFECYCLE)
    tracker.update([det(0.0, 0.0)], 0.0, "cam")
    tracker.update([det(0.0, 0.0)], 0.5, "cam")
    assert tracker.update([], 1.0, "cam").deleted == ()
    assert snap(tracker, 1).state is TrackState.TENTATIVE
    res = tracker.update([det(0.0, 0.0)], 1.25, "cam")  # third hit too late: 1.25 s after creation
    assert res.confirmed == () and res.deleted == (1,)
    assert tracker.stats.tracks_confirmed == 0


def test_lost_track_recovers_with_the_same_id() -> None:
    tracker = Tracker(LIFECYCLE)
    for t in (0.0, 0.25, 0.5):
        tracker.update([det(0.0, 0.0)], t, "cam")
    assert tracker.update([], 1.5, "cam").lost == (1,)
    res = tracker.update([det(0.1, 0.0)], 2.0, "cam")
    assert res.recovered == (1,) and res.associations == ((1, 0),) and res.created == ()
    assert snap(tracker, 1).state is TrackState.CONFIRMED


def test_track_timed_out_before_a_frame_does_not_take_its_detection() -> None:
    tracker = Tracker(LIFECYCLE)
    for t in (0.0, 0.25, 0.5):
        tracker.update([det(0.0, 0.0)], t, "cam")
    for k in range(3, 14):  # empty frames up to t = 3.25
        tracker.update([], k * 0.25, "cam")
    assert snap(tracker, 1).state is TrackState.LOST
    res = tracker.update([det(0.0, 0.0)], 3.75, "cam")  # track 1 expired at 3.5, between two frames
    assert res.deleted == (1,) and res.created == (2,) and res.associations == ((2, 0),)


def test_advance_applies_timeouts_without_frames() -> None:
    tracker = Tracker(LIFECYCLE)
    for t in (0.0, 0.25, 0.5):
        tracker.update([det(0.0, 0.0)], t, "cam")
    assert tracker.advance(1.0).lost == ()
    assert tracker.advance(1.5).lost == (1,)
    assert tracker.advance(1.2).status is FrameStatus.ADVANCED and tracker.clock_s == 1.5
    assert tracker.advance(3.5).deleted == (1,)


def test_tentative_track_converging_on_a_confirmed_one_is_merged_away() -> None:
    tracker = Tracker()
    for k in range(10):
        tracker.update([det(0.0, 0.0)], k / 10, "cam")
    assert tracker.update([det(0.0, 0.0), det(0.6, 0.0)], 1.0, "cam").created == (2,)
    assert tracker.update([det(0.0, 0.0), det(0.48, 0.0)], 1.1, "cam").deleted == ()
    res = tracker.update([det(0.0, 0.0), det(0.36, 0.0)], 1.2, "cam")
    assert (2, 1) in res.associations and res.deleted == (2,) and res.confirmed == ()
    assert tracker.stats.tracks_merged == 1 and tracker.track_ids() == [1]


def test_person_leaving_every_view_and_returning_gets_a_new_track() -> None:
    cfg = TrackerConfig(lost_after_s=1.0, delete_after_s=2.0)
    cam = CameraFov("a", (0.0, -4.0), math.pi / 2, math.radians(70), 6.0)
    # In view (|x| < 2.8 at y = 0) for ~2 s, then out to x = 6 and back: out of view for ~5.7 s.
    walker = Walker(1, ((-1.0, 0.0), (6.5, 0.0), (6.5, 1.0), (0.0, 1.0)), 1.2)
    frames = Scenario((walker,), (cam,), walker.end_s, noise_std_m=0.05, seed=0).frames()
    _, results = run(frames, cfg)
    reps = person_reports(frames, results)
    ids = [t for _, t in reps[1].track_sequence]
    first, second = ids[0], ids[-1]
    assert second > first
    deleted_at = next(r.stamp_s for r in results if first in r.deleted)
    reborn_at = next(r.stamp_s for r in results if second in r.created)
    last_seen = max(t for t, tid in reps[1].track_sequence if tid == first)
    assert deleted_at == pytest.approx(last_seen + 3.0, abs=1 / 30 + 1e-9)
    assert reborn_at > deleted_at
    assert sorted(set(ids)) == [first, second]


def test_duplicate_detections_of_one_person_start_one_track() -> None:
    tracker = Tracker()
    res = tracker.update([det(1.0, 1.0), det(1.15, 1.05), det(4.0, 4.0)], 0.0, "cam")
    assert res.created == (1, 2) and res.suppressed_detections == (1,)
    assert tracker.stats.detections_suppressed_near_track == 1


def test_track_limit_drops_and_counts_extra_detections() -> None:
    tracker = Tracker(TrackerConfig(max_tracks=2))
    res = tracker.update([det(0.0, 0.0), det(2.0, 0.0), det(4.0, 0.0)], 0.0, "cam")
    assert res.created == (1, 2) and res.rejected_detections == (2,) and tracker.num_tracks == 2
    assert tracker.stats.detections_dropped_track_limit == 1
