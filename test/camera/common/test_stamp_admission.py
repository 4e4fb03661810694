"""Stamps judged once at the edge (common.stamp_admission): the master's gate judges each frame's stamp once,
against its own clocks, and the tracker applies that verdict without judging again; the camera's gate owns the
image rules and the deadline its worker honours."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_camera.common.stamp_admission import ImageStampGate, StampClock
from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.records import CameraFrameRecord, PersonRecord


def _person(t: float) -> PersonRecord:
    return PersonRecord(np.array([0.5 * t, 1.0, 0.0]), 0.05, 1.75, None, 0.0, 0.8)


def _core() -> MasterCore:
    return MasterCore(MasterConfig(embedding_space="dlib_resnet_v1", body_appearance_tracking=False))


@pytest.mark.parametrize("live", [True, False])
def test_each_frame_stamp_is_judged_once_and_the_tracker_runs_on_the_gates_clock(monkeypatch, live: bool) -> None:
    core = _core()
    assert core.tracker._clock is core.admission.tracker_clock  # one clock: the gate's, moved by the tracker
    calls: list[float] = []
    judge = StampClock.admit

    def counted(self: StampClock, stamp: float, resync_backward: bool = True):  # type: ignore[no-untyped-def]
        calls.append(stamp)
        return judge(self, stamp, resync_backward)

    monkeypatch.setattr(StampClock, "admit", counted)
    stamps = [0.0, 0.1, 0.2, 0.15, 0.3, -20.0, 0.4]  # in order, a little late (applied late), far late (refused)
    outcomes = [core.process_frame(CameraFrameRecord("cam", t, (_person(t),)), now_s=0.45 if live else None)
                for t in stamps]
    assert len(calls) == len(stamps) - (1 if live else 0)  # live, -20.0 is refused as stale before the tracker clock
    assert [o.accepted for o in outcomes] == [True, True, True, True, True, False, True]
    assert core.tracker.stats.frames_out_of_order == 1 and core.tracker.clock_s == 0.4


def test_the_camera_gate_judges_images_and_sets_the_workers_deadline() -> None:
    gate = ImageStampGate(max_age_s=0.5)
    assert gate.admit("colour", 10.0, 10.05).accepted
    assert gate.admit("colour", 13.0, 10.05).code == "stamp_future"
    assert gate.admit("colour", 9.0, 10.05).code == "stamp_past"
    gate.paired(10.0)
    assert gate.admit("depth", 10.0, 10.06).code == "stamp_out_of_order"
    assert gate.admit("depth", 10.03, 10.08).accepted
    assert not gate.expired(10.03, 10.5) and gate.expired(10.03, 10.6)
    assert not ImageStampGate(0.0).expired(0.0, 1e9) and ImageStampGate(0.0).due_s("colour", 1.0) == math.inf
