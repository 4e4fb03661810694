"""The Tracker entry points (tracking.tracker): results, snapshots, reset, argument errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tracking_test_helpers import det, snap
from trajectories import (
    Scenario,
    overview_camera,
    random_walkers,
)

from face_reid_master.tracking.tracker import Tracker


def test_argument_errors_raise_value_error() -> None:
    # Detections are not re-checked (they come validated from MasterCore: see test_master_core.py);
    # the stamp and the config are the tracker's own arguments.
    tracker = Tracker()
    with pytest.raises(ValueError, match="stamp_s"):
        tracker.update([], math.nan, "a")
    with pytest.raises(ValueError, match="stamp_s"):
        tracker.update_arrays(np.zeros((0, 2)), np.zeros(0), np.zeros(0), math.inf, "a")
    with pytest.raises(ValueError, match="stamp_s"):
        tracker.advance(math.nan)
    with pytest.raises(ValueError, match="config"):
        Tracker({"lost_after_s": 1.0})  # type: ignore[arg-type]
    assert tracker.stats.frames_processed == 0
    tracker.update([det(0.0, 0.0)], 0.0, "a")
    with pytest.raises(ValueError, match="at_s"):
        tracker.snapshots(at_s=math.nan)


def test_results_and_snapshots_report_associations_heights_and_cameras() -> None:
    tracker = Tracker()
    r0 = tracker.update([det(0.0, 0.0, height_m=1.75), det(3.0, 0.0)], 0.0, "cam")
    assert r0.associations == ((1, 0), (2, 1)) and r0.created == (1, 2)
    r1 = tracker.update([det(3.0, 0.05), det(0.02, 0.0)], 0.1, "cam")
    assert r1.track_of_detection() == {0: 2, 1: 1}
    s1 = snap(tracker, 1)
    assert s1.height_m == 1.75 and s1.cameras == {"cam"} and s1.stamp_s == 0.1  # unknown height kept the old
    assert math.isnan(snap(tracker, 2).height_m)
    s = tracker.snapshots(at_s=1.0)[0]
    assert s.stamp_s == 1.0 and s.covariance.shape == (4, 4) and not s.position_xy.flags.writeable


def test_array_entry_equals_the_detection_entry() -> None:
    frames = Scenario(
        random_walkers(3, 0, area_m=6.0), (overview_camera(),), 3.0, 0.05, 0.2, latency_jitter_s=0.1, seed=2
    ).frames()
    by_detections, by_arrays = Tracker(), Tracker()
    for f in frames:
        a = by_detections.update(f.detections, f.stamp_s, f.camera_id)
        n = len(f.detections)
        b = by_arrays.update_arrays(
            np.array([d.position_xy for d in f.detections]).reshape(n, 2),
            np.array([d.position_std_m for d in f.detections]),
            np.array([d.height_m for d in f.detections]),
            f.stamp_s,
            f.camera_id,
        )
        assert a == b
    for sa, sb in zip(by_detections.snapshots(), by_arrays.snapshots(), strict=True):
        np.testing.assert_array_equal(sa.covariance, sb.covariance)
        assert (sa.track_id, sa.hits, sa.cameras) == (sb.track_id, sb.hits, sb.cameras)


def test_reset_deletes_everything_and_ids_keep_increasing() -> None:
    tracker = Tracker()
    tracker.update([det(0.0, 0.0), det(2.0, 0.0)], 0.0, "cam")
    assert tracker.reset() == (1, 2) and tracker.num_tracks == 0 and tracker.clock_s is None
    assert tracker.update([det(0.0, 0.0)], 0.0, "cam").created == (3,)
