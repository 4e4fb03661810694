"""Admission of frame stamps against the tracker clock (the newest accepted stamp; no wall clock).

Frames up to ``max_detection_delay_s`` older than the clock are applied late; older ones, and frames
more than ``max_future_stamp_s`` ahead, are rejected.  ``clock_resync_frames`` consecutive
rejections in the same direction are taken as a clock jump (cameras restarted after an idle period,
or a bag replay looping back) and the clock follows.
"""

from __future__ import annotations

from dataclasses import dataclass

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.lifecycle import EPS_S
from face_reid_master.tracking.records import FrameStatus

__all__ = ["Admission", "Clock"]


@dataclass(frozen=True, slots=True)
class Admission:
    """Verdict on one frame stamp.  ``resync``: the clock follows a jump; ``reset``: it jumped
    backwards, so every track must be deleted and the clock forgotten before applying the frame."""

    status: FrameStatus
    resync: bool = False
    reset: bool = False

    @property
    def accepted(self) -> bool:
        return self.status in (FrameStatus.APPLIED, FrameStatus.APPLIED_LATE)


_APPLIED = Admission(FrameStatus.APPLIED)
_APPLIED_LATE = Admission(FrameStatus.APPLIED_LATE)
_REJECTED_LATE = Admission(FrameStatus.REJECTED_LATE)
_REJECTED_FUTURE = Admission(FrameStatus.REJECTED_FUTURE)
_RESYNC_FORWARD = Admission(FrameStatus.APPLIED, resync=True)
_RESYNC_BACKWARD = Admission(FrameStatus.APPLIED, resync=True, reset=True)


class Clock:
    """The tracker clock and the run of rejected stamps that may re-base it."""

    def __init__(self, config: TrackerConfig) -> None:
        self._max_delay_s = config.max_detection_delay_s
        self._max_future_s = config.max_future_stamp_s
        self._resync_frames = config.clock_resync_frames
        self.now: float | None = None  # newest accepted stamp (None before the first frame)
        self._reject_run = 0
        self._reject_dir = 0  # +1 future, -1 late

    def admit(self, stamp: float, resync_backward: bool = True) -> Admission:
        """Classify ``stamp``; does not move the clock (see :meth:`follow`). ``resync_backward`` False: late
        stamps never re-base the clock (the caller checks stamps against a clock of its own: a camera that
        lags is refused, it cannot make the tracker start afresh)."""
        if self.now is None:
            self._reject_run = 0
            return _APPLIED
        if stamp > self.now + self._max_future_s + EPS_S:
            direction = 1
        elif stamp < self.now - self._max_delay_s - EPS_S:
            direction = -1
        else:
            self._reject_run = 0
            return _APPLIED_LATE if stamp < self.now else _APPLIED
        self._reject_run = self._reject_run + 1 if direction == self._reject_dir else 1
        self._reject_dir = direction
        if self._resync_frames and self._reject_run >= self._resync_frames and (direction > 0 or resync_backward):
            self._reject_run = 0
            # forward: an idle gap, time simply passed (lifecycle timeouts apply normally);
            # backward: time went back, start afresh
            return _RESYNC_FORWARD if direction > 0 else _RESYNC_BACKWARD
        return _REJECTED_FUTURE if direction > 0 else _REJECTED_LATE

    def follow(self, stamp: float) -> None:
        """Move the clock to ``stamp`` if that is newer."""
        if self.now is None or stamp > self.now:
            self.now = stamp

    def reset(self) -> None:
        """Forget the clock (and the run of rejections)."""
        self.now = None
        self._reject_run = 0
