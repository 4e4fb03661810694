"""Stamp admission (tracking.admission): too-late / future frames rejected, clock jumps re-synced."""

from __future__ import annotations

import numpy as np
from tracking_test_helpers import det, snap, straight_frames

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import FrameStatus
from face_reid_master.tracking.tracker import Tracker


def test_frames_older_than_the_bound_are_rejected_and_counted() -> None:
    tracker = Tracker(TrackerConfig(max_detection_delay_s=0.3))
    for t, c, d in straight_frames([0.0, 0.5, 1.0]):
        tracker.update(d, t, c)
    before = snap(tracker, 1)
    res = tracker.update([det(0.7, 0.35)], 0.69, "cam")
    assert res.status is FrameStatus.REJECTED_LATE and not res.accepted and res.associations == ()
    after = snap(tracker, 1)
    np.testing.assert_array_equal(after.covariance, before.covariance)
    assert after.hits == before.hits and tracker.stats.frames_rejected_late == 1
    assert tracker.update([det(0.71, 0.355)], 0.71, "cam").status is FrameStatus.APPLIED_LATE
    assert snap(tracker, 1).hits == before.hits + 1


def test_future_stamps_are_rejected_until_a_run_of_them_resyncs_the_clock() -> None:
    tracker = Tracker(TrackerConfig(max_future_stamp_s=1.0, clock_resync_frames=3))
    for t in (0.0, 0.1, 0.2):
        tracker.update([det(0.0, 0.0)], t, "cam")
    res = tracker.update([det(0.0, 0.0)], 50.0, "bad_clock")
    assert res.status is FrameStatus.REJECTED_FUTURE and tracker.clock_s == 0.2
    assert tracker.update([det(0.0, 0.0)], 0.3, "cam").status is FrameStatus.APPLIED  # run broken
    assert tracker.update([], 60.0, "x").status is FrameStatus.REJECTED_FUTURE
    assert tracker.update([], 60.1, "x").status is FrameStatus.REJECTED_FUTURE
    res = tracker.update([det(5.0, 5.0)], 60.2, "x")  # third in a row: cameras restarted after idling
    assert res.status is FrameStatus.APPLIED and res.clock_resync and tracker.clock_s == 60.2
    assert res.deleted == (1,) and res.created == (2,)  # the old track timed out in the gap
    assert tracker.stats.frames_rejected_future == 3 and tracker.stats.clock_resyncs == 1


def test_backward_clock_jump_resets_after_a_run_of_late_frames() -> None:
    tracker = Tracker(TrackerConfig(clock_resync_frames=2))
    for t in (100.0, 100.1):
        tracker.update([det(0.0, 0.0)], t, "cam")
    assert tracker.update([det(0.0, 0.0)], 3.0, "cam").status is FrameStatus.REJECTED_LATE
    res = tracker.update([det(0.0, 0.0)], 3.1, "cam")  # bag replay looped: start afresh
    assert res.clock_resync and res.deleted == (1,) and res.created == (2,) and tracker.clock_s == 3.1
