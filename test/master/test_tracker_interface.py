"""The tracker is a component MasterCore is given: any object of the MultiCameraTracker shape drives it, and
its own configuration is the one the core reads (no second copy to disagree with)."""

from __future__ import annotations

import numpy as np

from face_reid_camera.common.stamp_admission import ClockVerdict
from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.interface import FrameDetections, MultiCameraTracker
from face_reid_master.tracking.records import TrackerStats, UpdateResult
from face_reid_master.tracking.tracker import Tracker


class _CountingTracker:
    """The project's tracker behind the interface, counting the frames it is given."""

    def __init__(self, config: TrackerConfig) -> None:
        self._inner = Tracker(config)
        self.frames = 0
        self.config = config
        self.advance = self._inner.advance
        self.reset = self._inner.reset
        self.reserve_id = self._inner.reserve_id
        self.snapshots = self._inner.snapshots
        self.clock = self._inner.clock

    @property
    def stats(self) -> TrackerStats:
        return self._inner.stats

    def update_frame(self, detections: FrameDetections, stamp_s: float, camera_id: str, *,
                     resync_backward: bool = True, admitted: ClockVerdict | None = None) -> UpdateResult:
        self.frames += 1
        return self._inner.update_frame(detections, stamp_s, camera_id, resync_backward=resync_backward,
                                        admitted=admitted)


def _frame(t: float, x: float) -> CameraFrameRecord:
    return CameraFrameRecord("cam", t, (PersonRecord(np.array([x, 0.0, 0.0]), 0.05, 1.75, None, 0.9, 0.8),))


def test_master_core_runs_an_injected_tracker_with_its_configuration() -> None:
    tracker_config = TrackerConfig(lost_after_s=0.3, delete_after_s=0.6, max_detection_delay_s=0.25)
    tracker = _CountingTracker(tracker_config)
    typed: MultiCameraTracker = tracker  # the shape is checked by the type checker too
    core = MasterCore(MasterConfig(), tracker=typed)
    assert core.tracker is tracker and core.config.tracker == tracker_config  # one configuration, the tracker's
    outcomes = [core.process_frame(_frame(0.1 * k, 0.05 * k)) for k in range(10)]
    assert tracker.frames == 10 and all(o.accepted for o in outcomes)
    (track,) = core.tracks()
    assert outcomes[-1].track_of_person == {0: track.track_id}
    core.tick(2.0)  # the tracker's own timeouts delete the track
    assert core.tracks() == []
