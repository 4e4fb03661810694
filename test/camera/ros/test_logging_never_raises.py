"""Logging never ends a node: rclpy ties a line of code to the severity of its first log call and raises
ValueError when the same line logs at another, so a node whose throttled logger sent WARN and ERROR through one
call died on the first rejection of the other kind. Every node kind (camera, master, map, goto) in one process
is fed its rejections at every severity in turn, on the same and on different keys, and still answers."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from conftest import spin_until

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from sensor_msgs.msg import Image

pytestmark = pytest.mark.ros

OK = TransitionCallbackReturn.SUCCESS


class _Pub:
    """A stand-in /diagnostics publisher (the diagnostics path runs without activating the node)."""

    def publish(self, msg: Any) -> None:
        pass


def _diagnostics_fail(node: Any, monkeypatch: pytest.MonkeyPatch) -> Callable[[], None]:
    """ManagedNode's own ERROR path: building the diagnostics raised (logged, the node carries on)."""

    def broken(now_s: float) -> Any:
        raise RuntimeError("diagnostics broke (test)")

    def run() -> None:
        monkeypatch.setattr(node, "diagnostics", broken)
        node._diagnostics_pub = _Pub()
        try:
            node._publish_diagnostics()
        finally:
            node._diagnostics_pub = None
            monkeypatch.undo()

    return run


def test_every_node_kind_logs_rejections_at_every_severity_in_turn_and_carries_on(
        ros_context, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> None:
    from face_reid_camera.ros.node import CameraNode
    from face_reid_master.ros.goto_node import GotoNode
    from face_reid_master.ros.map_node import MapNode
    from face_reid_master.ros.node import MasterNode
    from face_reid_msgs.msg import FloorOccupancy

    ctx = ros_context()
    camera, master, fmap, goto = (CameraNode(context=ctx), MasterNode(context=ctx), MapNode(context=ctx),
                                  GotoNode(context=ctx))
    nodes = (camera, master, fmap, goto)
    try:
        assert fmap.trigger_configure() == OK  # its summaries go to the fusion it builds
        bad_image = Image(encoding="no-such-encoding", height=2, width=2, step=2, data=b"\x00" * 4)
        # each node's real rejection paths (ERROR / WARN) and the shared helper at both severities on one key
        rejections: dict[str, list[Callable[[], None]]] = {
            "camera": [lambda: camera._on_color(bad_image),  # ERROR: colour image rejected (bad_color)
                       lambda: camera.log_throttled("bad_color", "same key, WARN", warn=True),
                       lambda: camera.log_throttled("sync_reset", "image stamps went back (test)", 1, warn=True),
                       _diagnostics_fail(camera, monkeypatch)],
            "master": [lambda: master._reject("frame_id", "frame in the wrong frame (test)"),  # WARN
                       lambda: master.log_throttled("frame_id", "same key, ERROR"),
                       _diagnostics_fail(master, monkeypatch)],
            "map": [lambda: fmap._on_summary(FloorOccupancy(camera_id="cam_x")),  # WARN: summary rejected
                    lambda: fmap.log_throttled("fuse", "cannot fuse (test)"),  # ERROR, as publish_grid's
                    _diagnostics_fail(fmap, monkeypatch)],
            "goto": [lambda: goto._reject("robot_pose", "robot pose in frame 'x' (test)"),  # WARN
                     lambda: goto.log_throttled("robot_pose", "same key, ERROR"),
                     _diagnostics_fail(goto, monkeypatch)],
        }
        for _round in range(3):  # WARN after ERROR after WARN ... on each line of code
            for node, paths in zip(nodes, rejections.values(), strict=True):
                for path in paths:
                    node._last_logged.clear()  # not held back by the throttle: every call reaches rclpy
                    path()
        for node in nodes:  # the unthrottled helper, at each level in turn
            for level in ("info", "warn", "error", "warn", "info", "error"):
                node.log(f"{level} line (test)", level)
        err = capfd.readouterr().err
        for text in ("colour image rejected", "same key, WARN", "image stamps went back (test)",
                     "diagnostics failed: RuntimeError", "frame in the wrong frame (test)", "same key, ERROR",
                     "floor summary rejected", "cannot fuse (test)", "robot pose in frame 'x' (test)"):
            assert text in err, text
        assert "logging failed" not in err  # no line fell back to the emergency writer
        assert camera.health is None and master._reject is not None
        # and every node still answers: its state, and (the map) a transition
        assert [n.state_label() for n in nodes] == ["unconfigured", "unconfigured", "inactive", "unconfigured"]
        assert fmap.trigger_cleanup() == OK
    finally:
        for node in nodes:
            node.destroy_node()


def test_a_private_line_stays_off_rosout_on_a_secured_node_and_reaches_it_on_an_unsecured_one(
        ros_context, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """The private log path (names, file paths, track/face assignments): stderr on both, /rosout only without a
    network key."""
    from rcl_interfaces.msg import Log
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_rosout_default

    from face_reid_camera.common.sealing import write_network_key
    from face_reid_master.ros.map_node import MapNode

    key = write_network_key(tmp_path / "network.key")
    ctx = ros_context()
    secured = MapNode(context=ctx, namespace="/secured",
                      parameter_overrides=[Parameter("network_key_path", value=str(key))])
    open_ = MapNode(context=ctx, namespace="/open")
    listener = Node("rosout_listener", context=ctx)
    heard: list[tuple[str, str]] = []
    listener.create_subscription(Log, "/rosout", lambda m: heard.append((m.name, m.msg)), qos_profile_rosout_default)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (secured, open_, listener):
        executor.add_node(node)
    try:
        assert secured.secured and not open_.secured
        assert spin_until(executor, lambda: listener.count_publishers("/rosout") >= 3)
        for node in (secured, open_):
            node.log(f"added Alice-{node.get_namespace()[1:]} from /home/op/gallery", private=True)
            node.log_throttled("names", f"forgot Bob-{node.get_namespace()[1:]}", private=True)
            node.log(f"public line of {node.get_namespace()[1:]}")  # after the private ones: a barrier
        assert spin_until(executor, lambda: sum(m.startswith("public line of") for _, m in heard) == 2), heard
        said = " | ".join(m for _, m in heard)
        assert "Alice-open" in said and "Bob-open" in said  # unsecured: today's behaviour
        assert "Alice-secured" not in said and "Bob-secured" not in said and "/home/op" not in said.replace(
            "added Alice-open from /home/op/gallery", "")
        err = capfd.readouterr().err
        # the secured node's private lines are in its local log, under <node logger>.local
        assert "[secured.face_reid_map.local]: added Alice-secured from /home/op/gallery" in err, err[-2000:]
        assert "forgot Bob-secured" in err
    finally:
        executor.shutdown()
        for node in (secured, open_, listener):
            node.destroy_node()


@pytest.mark.slow
def test_a_secured_camera_that_logged_an_error_survives_an_unsealed_control_call(ros_domain_id: int, ros_context,
                                                                                 tmp_path: Path) -> None:
    """The attack as it was found (real process, real DDS): an ERROR-level input rejection, then one keyless,
    unsealed ~/change_state_sealed call (refused: a WARN from the same throttled logger). The camera answers,
    stays active and goes on publishing /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray
    from ros_procs import procs

    from face_reid_camera.common.sealing import write_network_key
    from face_reid_msgs.srv import ChangeState

    key = write_network_key(tmp_path / "network.key")
    log = tmp_path / "camera.log"
    camera = procs.start(["-m", "face_reid_camera.ros.node", "--ros-args", "-r", "__ns:=/cam_a",
                          "-p", "camera_id:=cam_a", "-p", f"network_key_path:={key}"], ros_domain_id, log)
    ctx = ros_context()
    peer = Node("peer", context=ctx)
    reports: list[dict[str, str]] = []

    def on_diagnostics(msg: Any) -> None:
        reports.extend({kv.key: kv.value for kv in s.values} for s in msg.status if s.hardware_id == "cam_a")

    peer.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    colour = peer.create_publisher(Image, "/cam_a/color/image_raw", 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    try:
        assert spin_until(executor, lambda: reports and colour.get_subscription_count() > 0, 180.0), log.read_text()
        def rejected_once() -> bool:  # published again until one reaches the camera's current subscription
            bad = Image(encoding="no-such-encoding", height=2, width=2, step=2, data=b"\x00" * 4)
            bad.header.stamp = peer.get_clock().now().to_msg()  # fresh: judged by its encoding, not its age
            colour.publish(bad)
            return int(reports[-1].get("rejected_bad_color", "0")) >= 1

        assert spin_until(executor, rejected_once, 60.0), log.read_text()
        assert "colour image rejected" in log.read_text()  # the ERROR line
        client = peer.create_client(ChangeState, "/cam_a/face_reid_camera/change_state_sealed")
        assert spin_until(executor, client.service_is_ready, 60.0)
        future = client.call_async(ChangeState.Request(transition="shutdown"))  # plain: no key
        assert spin_until(executor, future.done, 60.0), log.read_text()
        reply = future.result()
        assert not reply.success and "must be sealed" in reply.message  # plain refusal: why, no state
        seen = len(reports)
        assert spin_until(executor, lambda: len(reports) >= seen + 2, 60.0), log.read_text()  # still publishing
        assert camera.poll() is None, log.read_text()
        assert "Logger severity cannot be changed" not in log.read_text()
    finally:
        executor.shutdown()
        peer.destroy_node()
        procs.stop(camera)


def test_the_map_and_goto_nodes_count_sealed_control_requests_on_diagnostics(ros_context) -> None:
    """Every node kind with ``~/change_state_sealed`` reports its requests and refusals (the camera's and the
    master's are checked with their DDS tests)."""
    from face_reid_master.ros.goto_node import GotoNode
    from face_reid_master.ros.map_node import MapNode

    ctx = ros_context()
    fmap, goto = MapNode(context=ctx), GotoNode(context=ctx)
    try:
        assert fmap.trigger_configure() == OK and goto.trigger_configure() == OK
        for node in (fmap, goto):
            node.control_requests, node.control_refusals = 3, 2
            values = node.diagnostics(node.now_s()).values
            assert (values["control_requests"], values["control_refused"]) == ("3", "2"), values
    finally:
        fmap.destroy_node()
        goto.destroy_node()
