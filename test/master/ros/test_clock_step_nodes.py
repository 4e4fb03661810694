"""The master and camera nodes in-process with their host's wall clock stepping +120 s and back (their module's
``time`` replaced in the test: no runtime switch): /diagnostics says ERROR while it lasts and counts the steps,
and every timer runs on the monotonic clock, so none waits for a stepped clock's old future (before, /diagnostics
and the master's ticks stayed silent for the step's length)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

from rclpy.clock import ClockType
from rclpy.lifecycle import TransitionCallbackReturn

import face_reid_camera.ros.node as camera_node
import face_reid_master.ros.node as master_node
from face_reid_camera.ros.node import CameraNode
from face_reid_master.ros.node import MasterNode

OK = TransitionCallbackReturn.SUCCESS


class _SteppedTime:
    """time.time() off by ``offset`` s; monotonic untouched."""

    def __init__(self) -> None:
        self.offset = 0.0

    def time(self) -> float:
        return time.time() + self.offset

    @staticmethod
    def monotonic() -> float:
        return time.monotonic()

    @staticmethod
    def perf_counter() -> float:
        return time.perf_counter()

    @staticmethod
    def sleep(s: float) -> None:
        time.sleep(s)


def _levels_through_a_step(node, module, monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, str]]:
    clock = _SteppedTime()
    monkeypatch.setattr(module, "time", clock)
    out = []
    for offset in (0.0, 120.0, 120.0, 0.0):
        clock.offset = offset
        report = node.diagnostics(node.now_s())
        out.append((int(report.level), report.message))
    return out


def test_the_masters_diagnostics_say_error_while_its_clock_is_stepped_and_its_timers_are_steady(
        ros_context, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "camera_topic_regex:=''",
                       "-p", "embedding_space:=dlib_resnet_v1", "-p", "max_publish_rate_hz:=10.0"])
    node = MasterNode(context=ctx)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        timers = [*node._own_timers, node._diagnostics_timer]
        assert len(timers) == 5 and all(t.clock.clock_type == ClockType.STEADY_TIME for t in timers)
        levels = _levels_through_a_step(node, master_node, monkeypatch)
        assert [lv for lv, _ in levels][1:3] == [2, 2] and levels[0][0] < 2 and levels[3][0] < 2, levels
        assert "clock stepped +120.0 s" in levels[1][1]
        values = node.diagnostics(node.now_s()).values
        assert values["clock_steps"] == "2" and values["clock_stepped"] == "False"
    finally:
        node.destroy_node()


def test_the_cameras_diagnostics_say_error_while_its_clock_is_stepped(
        ros_context, monkeypatch: pytest.MonkeyPatch) -> None:
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_clock", "-p", "detect_faces:=false",
                       "-p", "describe_bodies:=false", "-p", "image_qos:=auto"])
    node = CameraNode(context=ctx)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        assert all(t.clock.clock_type == ClockType.STEADY_TIME for t in (node._qos_timer, node._diagnostics_timer))
        levels = _levels_through_a_step(node, camera_node, monkeypatch)
        assert [lv for lv, _ in levels][1:3] == [2, 2] and levels[0][0] < 2 and levels[3][0] < 2, levels
        assert "clock stepped +120.0 s" in levels[1][1] and "master refuses" in levels[1][1]
        assert node.diagnostics(node.now_s()).values["clock_steps"] == "2"
    finally:
        node.destroy_node()
