"""Which frames the master applies: every rule a camera frame must pass before it reaches the tracker.

A frame is refused whole for a stamp that is not a number, an unknown or empty camera id, too many people, a
camera sending faster than ``max_camera_rate_hz``, or for its stamp: the stamp is judged once, here, by
:class:`~face_reid_camera.common.stamp_admission.FrameStampGate` (the caller's clock: too old, too far ahead, a
little ahead applied at the caller's clock, the caller's clock gone back; then the tracker clock: too late, too far
ahead, a run of those re-basing it). The tracker is handed the verdict (:attr:`Admission.tracker`) and its clock
is the gate's (:attr:`FrameAdmission.tracker_clock`): it does not judge the stamp again.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from face_reid_camera.common.checks import shown
from face_reid_camera.common.stamp_admission import ClockVerdict, FrameStampGate, StampClock, finite_stamp
from face_reid_master.core.config import MasterConfig
from face_reid_master.core.records import MasterStats
from face_reid_master.records import CameraFrameRecord

__all__ = ["Admission", "FrameAdmission"]

_MAX_CAMERAS = 1024  # cameras whose frame rate is followed at most (the least recent go first)


@dataclass(frozen=True)
class Admission:
    """The verdict on one frame: the stamp it is applied at, or the rejection's ``code`` and ``reason``."""

    stamp_s: float
    code: str = ""  # '' = admitted
    reason: str = ""
    clock_went_back: bool = False  # the caller's clock went back: tracking must start afresh first
    tracker: ClockVerdict | None = None  # the tracker clock's verdict, handed to the tracker (None: refused before)

    @property
    def admitted(self) -> bool:
        return not self.code


class FrameAdmission:
    """The rejection rules of the master's frame path (see the module doc); counts into ``stats``."""

    def __init__(self, config: MasterConfig, stats: MasterStats, tracker_clock: StampClock | None = None) -> None:
        """``tracker_clock``: an injected tracker's clock to judge stamps against (default: the gate's own, given to
        the project's tracker)."""
        self.config = config
        self.stats = stats
        tc = config.tracker
        self.gate = FrameStampGate(config.max_stamp_age_s, config.max_stamp_future_s, tc.max_detection_delay_s,
                                   tc.max_future_stamp_s, tc.clock_resync_frames)
        if tracker_clock is not None:
            self.gate.tracker_clock = tracker_clock
        self._camera_frames: dict[str, deque[float]] = {}  # camera -> its frames' times in the last second

    def admit(self, frame: CameraFrameRecord, now_s: float | None) -> Admission:
        """The verdict on ``frame`` at the caller's clock ``now_s`` (None: offline, stamps are the clock)."""
        cfg, st = self.config, self.stats
        st.frames_received += 1
        stamp = finite_stamp(frame.stamp_s)
        if math.isnan(stamp):
            st.frames_rejected_bad_stamp += 1
            return Admission(stamp, "bad_stamp", "stamp is not a finite number")
        if cfg.known_camera_ids and frame.camera_id not in cfg.known_camera_ids:
            st.frames_rejected_unknown_camera += 1
            return Admission(stamp, "unknown_camera", f"unknown camera id {shown(frame.camera_id, 64)}")
        if not isinstance(frame.camera_id, str) or not frame.camera_id:
            st.frames_rejected_unknown_camera += 1
            return Admission(stamp, "unknown_camera",
                             "empty camera id" if frame.camera_id == "" else "camera id is not a str")
        if len(frame.people) > cfg.max_people_per_frame:
            st.frames_rejected_too_many_people += 1
            return Admission(stamp, "too_many_people",
                             f"{len(frame.people)} people in one frame (> max_people_per_frame)")
        if not self._camera_rate_ok(frame.camera_id, stamp if now_s is None else now_s):
            st.frames_rejected_camera_rate += 1
            return Admission(stamp, "camera_rate", f"camera sends more than {cfg.max_camera_rate_hz:g} frames/s")
        verdict = self.gate.admit(stamp, now_s)
        if verdict.code:
            if verdict.code == "stale_stamp":
                st.frames_rejected_stale += 1
            else:
                st.frames_rejected_future += 1
            return Admission(verdict.stamp_s, verdict.code, verdict.reason)
        st.clock_jumps_back += verdict.clock_went_back
        st.frames_future_clamped += verdict.clamped
        return Admission(verdict.stamp_s, clock_went_back=verdict.clock_went_back, tracker=verdict.tracker)

    @property
    def tracker_clock(self) -> StampClock:
        """The tracker clock the gate compares stamps against (the tracker moves it: it is given this one)."""
        return self.gate.tracker_clock

    def clock_went_back(self, now_s: float) -> bool:
        """Whether the caller's clock ``now_s`` (a tick's) went back by more than ``max_detection_delay_s``
        (counted in ``clock_jumps_back``: tracking must start afresh); see FrameStampGate.clock_went_back."""
        went_back = self.gate.clock_went_back(now_s)
        self.stats.clock_jumps_back += went_back
        return went_back

    def _camera_rate_ok(self, camera_id: str, now_s: float) -> bool:
        """Whether the camera sent fewer than ``max_camera_rate_hz`` frames in the second before ``now_s``
        (then this one is counted); at most _MAX_CAMERAS cameras are remembered (the least recent go first)."""
        times = self._camera_frames.get(camera_id)
        if times is None:
            if len(self._camera_frames) >= _MAX_CAMERAS:
                oldest = min(self._camera_frames, key=lambda c: self._camera_frames[c][-1])  # never empty
                del self._camera_frames[oldest]
            times = self._camera_frames[camera_id] = deque()
        while times and (times[0] <= now_s - 1.0 or times[0] > now_s + 1.0):
            times.popleft()
        if len(times) >= self.config.max_camera_rate_hz:
            return False
        times.append(now_s)
        return True
