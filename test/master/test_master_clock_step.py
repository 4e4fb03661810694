"""The master's clock steps +120 s for 5 s and back (break 5): the real MasterCore, CycleSchedule, OutputStamps,
Opener / Sealer and ClockStepDetector driven with that clock, as the node drives them. During the step the
camera's frames are refused (counted) and /diagnostics says ERROR; within 5 s of the correction a consumer with
the key gets tracks again (before: 0 tracks for ~120 s, the frames "late" and the seals "stale")."""

from __future__ import annotations

import math

import numpy as np
import pytest

import face_reid_camera.common.sealing as sealing
from face_reid_camera.common.clock_step import ClockStepDetector
from face_reid_camera.common.sealing import Opener, Sealer, SealError
from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.cycle_schedule import CycleSchedule
from face_reid_master.output_stamps import OutputStamps
from face_reid_master.records import CameraFrameRecord, PersonRecord

KEY = bytes(range(32))
T0 = 1.7e9  # the true time at the start (s since the epoch)
STEP_S, STEP_FROM, STEP_UNTIL = 120.0, 20.0, 25.0  # the master's clock error and when (true s from start)


class _Clocks:
    """The sealing module's time: the clock of whoever seals now (the camera's true one, the master's stepped)."""

    def __init__(self) -> None:
        self.now = T0

    def time(self) -> float:
        return self.now

    def time_ns(self) -> int:
        return int(self.now * 1e9)

    @staticmethod
    def monotonic() -> float:
        return 0.0


def _person(t: float) -> PersonRecord:
    return PersonRecord(np.array([0.2 * math.sin(t / 5), 1.0, 0.0]), 0.05, 1.75, None, 0.0, 0.8)


def test_a_masters_clock_stepping_ahead_and_back_leaves_it_silent_for_seconds_not_minutes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    clocks = _Clocks()
    monkeypatch.setattr(sealing, "time", clocks)
    core = MasterCore(MasterConfig(embedding_space="dlib_resnet_v1", body_appearance_tracking=False))
    delay = core.config.tracker.max_detection_delay_s
    schedule, stamps, detector = CycleSchedule(max_publish_rate_hz=10.0), OutputStamps(), ClockStepDetector()
    camera, frames_in = Sealer(KEY, "cam_a"), Opener(KEY, "frames", 30.0, not_before_s=T0)
    master, consumer = Sealer(KEY, "/face_reid_master", "tracks"), Opener(KEY, "tracks", 30.0, not_before_s=T0)
    with_tracks: list[float] = []  # true seconds at which the consumer opened tracks with someone in them
    errors: list[float] = []  # true seconds at which /diagnostics said ERROR
    refused = 0
    for k in range(600):  # 60 s at 10 Hz
        t = k / 10
        true_now = T0 + t
        master_now = true_now + (STEP_S if STEP_FROM <= t < STEP_UNTIL else 0.0)
        clocks.now = true_now
        sealed = camera.seal(b"frame")
        try:  # the frame receiver: opened by the master's clock
            frames_in.open(sealed, master_now)
        except SealError:
            refused += 1
        else:
            core.process_frame(CameraFrameRecord("cam_a", true_now - 0.05, (_person(t),)), master_now)
        core.tick(master_now - delay)  # the node's tick
        if schedule.may_publish(master_now, core.time_s):
            stamps.next(core.time_s, master_now)
            clocks.now = master_now
            out = master.seal(b"tracks")
            try:
                consumer.open(out, true_now)  # a consumer whose clock is right
            except SealError:
                pass
            else:
                if core.tracks():
                    with_tracks.append(t)
        if k % 10 == 0:  # the diagnostics timer (steady)
            detector.update(master_now, t)
            detector.count_refused(refused)
            if detector.stepped:
                errors.append(t)
    after = [t for t in with_tracks if t >= STEP_UNTIL]
    assert after and after[0] - STEP_UNTIL <= 5.0, f"tracks again at {after[:1]} s (the correction at {STEP_UNTIL} s)"
    assert len([t for t in after if t >= STEP_UNTIL + 5.0]) >= 0.9 * 10 * (60 - STEP_UNTIL - 5.0)
    assert not any(STEP_FROM <= t < STEP_UNTIL for t in with_tracks)  # the frames are refused meanwhile
    assert errors == [20.0, 21.0, 22.0, 23.0, 24.0]
    assert detector.steps == 2 and detector.refused_during_steps == 50
    assert core.stats.clock_jumps_back == 1


def test_a_tick_at_the_stepped_clock_does_not_make_the_corrected_frames_late() -> None:
    """Admission after a step: the tick moved the tracker 120 s ahead; the corrected clock restarts tracking
    at its first tick or frame, and the frames are applied (before: rejected as late for 120 s)."""
    core = MasterCore(MasterConfig(embedding_space="dlib_resnet_v1", body_appearance_tracking=False))
    for k in range(20):
        assert core.process_frame(CameraFrameRecord("cam_a", k / 10, (_person(k / 10),)), k / 10 + 0.05).accepted
    core.tick(2.0 + STEP_S)  # the master's clock ahead: every track times out
    core.tick(2.1)  # corrected
    outcomes = [core.process_frame(CameraFrameRecord("cam_a", 2.1 + k / 10, (_person(k / 10),)), 2.15 + k / 10)
                for k in range(10)]
    assert all(o.accepted for o in outcomes) and core.stats.frames_rejected_tracker_late == 0
    assert core.stats.clock_jumps_back == 1 and len(core.tracks()) == 1
