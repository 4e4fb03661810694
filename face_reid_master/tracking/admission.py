"""The tracker's view of stamp admission: its clock and verdicts, from the one gate that judges stamps.

The rules (frames up to ``max_detection_delay_s`` older than the clock are applied late; older ones, and frames
more than ``max_future_stamp_s`` ahead, are refused; ``clock_resync_frames`` consecutive refusals in one direction
re-base the clock) live in :class:`~face_reid_camera.common.stamp_admission.StampClock`. Inside MasterCore the
frame's stamp is judged once at its edge (core.admission) and the tracker is handed that verdict and the gate's
clock; a Tracker used alone judges each stamp with its own clock, by the same rules.
"""

from __future__ import annotations

from dataclasses import dataclass

from face_reid_camera.common.stamp_admission import ClockVerdict, StampClock
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import FrameStatus

__all__ = ["Admission", "Clock", "as_admission", "verdict_on"]


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


_VERDICTS: dict[ClockVerdict, Admission] = {}


def as_admission(verdict: ClockVerdict) -> Admission:
    """The tracker's Admission of a gate's ClockVerdict (the same status, resync and reset)."""
    admission = _VERDICTS.get(verdict)
    if admission is None:
        admission = _VERDICTS[verdict] = Admission(FrameStatus(verdict.status), verdict.resync, verdict.reset)
    return admission


class Clock(StampClock):
    """The tracker clock and the run of refused stamps that may re-base it, configured from a TrackerConfig."""

    def __init__(self, config: TrackerConfig) -> None:
        super().__init__(config.max_detection_delay_s, config.max_future_stamp_s, config.clock_resync_frames)


def verdict_on(clock: StampClock, stamp: float, resync_backward: bool, admitted: ClockVerdict | None) -> Admission:
    """The tracker's verdict on ``stamp``: the gate's ``admitted`` (judged at the edge against ``clock``: not judged
    again, only the invariant that a late verdict is behind the clock is asserted), else ``clock`` judges it."""
    if admitted is None:
        return as_admission(clock.admit(stamp, resync_backward))
    assert admitted.status != "applied_late" or (clock.now is not None and stamp < clock.now)
    return as_admission(admitted)
