"""A secured face-reid-goto (network key) over real DDS: only a holder of the key sets its target, and the target's
name goes out only sealed. A keyless peer finds no ~/target topic to publish on and its plain or wrongly sealed
~/go_to requests are refused (counted on /diagnostics), so the robot keeps going to Alice; nothing is published
on ~/status and /diagnostics names nobody; the sealed status opens with the key and names the target; the
operator's sealed request (face-reid-goto --send NAME --key KEY) sends the robot to Bob and gets a sealed reply,
and the client takes no reply from a keyless server on the same service name.
The unsecured goto's plain topic, service and status are covered by test_goto_dds.py."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import REPO_ROOT, spin_until
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from face_reid_camera.common.ros.sealed import open_response, seal_message, seal_request
from face_reid_camera.common.sealing import Opener, Sealer, load_network_key, write_network_key
from face_reid_master.ros.goto_client import StatusReader
from face_reid_master.tracks_auth import TRACKS_PURPOSE
from face_reid_msgs.msg import NamedTrack, NamedTrackArray, Sealed
from face_reid_msgs.srv import GoToPerson

pytestmark = pytest.mark.ros

GOTO = "/face_reid_goto"
START_S = 120.0  # a loaded machine: the goto process starts while other tests run
ALICE_Y, BOB_Y = 0.0, 4.0  # where they walk (world = map: no transform file)


def _tracks(k: int) -> NamedTrackArray:
    """Alice and Bob, confirmed, walking along x (so that goals keep coming), far apart in y."""
    msg = NamedTrackArray()
    msg.header.frame_id = "world"
    for tid, name, y in ((1, "Alice", ALICE_Y), (2, "Bob", BOB_Y)):
        t = NamedTrack(track_id=tid, face_id=tid, name=name, identity_confidence=0.9, state=NamedTrack.STATE_CONFIRMED)
        t.position.x, t.position.y = 0.05 * k, y
        msg.tracks.append(t)
    return msg


def _latched(depth: int = 10) -> QoSProfile:
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _person_y(goal: PoseStamped, standoff_m: float = 1.0) -> float:
    """The y of the person a goal faces (one stand-off ahead of it)."""
    yaw = 2.0 * math.atan2(goal.pose.orientation.z, goal.pose.orientation.w)
    return goal.pose.position.y + standoff_m * math.sin(yaw)


def test_a_keyless_peer_cannot_steer_a_secured_goto_nor_read_its_target(ros_domain_id: int, ros_context,
                                                                         tmp_path: Path) -> None:
    key_path = write_network_key(tmp_path / "network.key")
    key = load_network_key(key_path)
    stranger_key = load_network_key(write_network_key(tmp_path / "stranger.key"))
    goto = procs.start(["-m", "face_reid_master.ros.goto_node", "Alice", "--ros-args",
                        "-p", f"network_key_path:={key_path}", "-p", "names_service:=''",
                        "-p", "min_goal_interval_s:=0.0", "-p", "reissue_distance_m:=0.1"],
                       ros_domain_id, tmp_path / "goto.log")
    ctx = ros_context()
    peer = Node("peer", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    logs = lambda: (tmp_path / "goto.log").read_text()[-4000:]  # noqa: E731

    # the master's sealed tracks (what a secured goto reads), a new message every 0.1 s
    tracks_sealer = Sealer(key, "/face_reid_master", TRACKS_PURPOSE)
    tracks_pub = peer.create_publisher(Sealed, "/tracks_named_sealed", 10)
    k = [0]

    def publish_tracks() -> None:
        k[0] += 1
        tracks_pub.publish(seal_message(tracks_sealer, _tracks(k[0])))

    peer.create_timer(0.1, publish_tracks)
    goals: list[PoseStamped] = []
    plain_status: list[str] = []
    opened: list[str] = []  # the sealed status, opened with the key
    diagnostics: dict[str, str] = {}
    peer.create_subscription(PoseStamped, "/goal_pose", goals.append, 50)
    peer.create_subscription(String, f"{GOTO}/status", lambda m: plain_status.append(m.data), _latched())
    status = StatusReader(peer, opened.append, str(key_path), GOTO)
    peer.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diagnostics.update(
        {kv.key: kv.value for s in m.status if s.hardware_id == GOTO for kv in s.values}), 50)
    target = peer.create_publisher(String, f"{GOTO}/target", 10)
    go_to = peer.create_client(GoToPerson, f"{GOTO}/go_to")

    def call(request: Any) -> Any:
        future = go_to.call_async(request)
        assert spin_until(executor, future.done, 60.0), logs()
        return future.result()

    def goals_for(y: float, since: int) -> bool:
        return len(goals) >= since + 3 and all(abs(_person_y(g) - y) < 0.5 for g in goals[since + 1:])

    try:
        # the goto goes to Alice (from the command line); its status is readable only with the key
        assert spin_until(executor, lambda: any("goal for 'Alice'" in s for s in opened), START_S), (opened, logs())
        assert spin_until(executor, lambda: go_to.service_is_ready() and "go_to_refused" in diagnostics, 60.0), logs()
        assert goals and abs(_person_y(goals[-1]) - ALICE_Y) < 0.5  # the goals stay plain PoseStamped in the map
        assert not peer.get_publishers_info_by_topic(f"{GOTO}/status") and not plain_status

        # the keyless peer: no ~/target topic to publish on (what it publishes there reaches nobody) ...
        assert not peer.get_subscriptions_info_by_topic(f"{GOTO}/target")
        for _ in range(5):
            target.publish(String(data="Bob"))
        # ... a plain go_to, one sealed with another key, one sealed for another node: refused, plainly
        reply = call(GoToPerson.Request(name="Bob"))
        assert not reply.accepted and "must be sealed" in reply.status and not reply.sealed_response.ciphertext
        reply = call(seal_request(Sealer(stranger_key, "stranger"), GoToPerson.Request(name="Bob"), GOTO))
        assert not reply.accepted and "network's key" in reply.status and not reply.sealed_response.ciphertext
        reply = call(seal_request(Sealer(key, "elsewhere"), GoToPerson.Request(name="Bob"), "/other_goto"))
        assert not reply.accepted and "not for this node" in reply.status and not reply.sealed_response.ciphertext
        assert spin_until(executor, lambda: diagnostics.get("go_to_refused") == "3", 30.0), diagnostics
        # the target stays: the goals still face Alice as she walks, the status still names her
        n = len(goals)
        assert spin_until(executor, lambda: goals_for(ALICE_Y, n), 30.0), [_person_y(g) for g in goals[n:]]
        assert "Bob" not in opened[-1] and "goal for 'Alice'" in opened[-1], opened[-1]
        assert not any("Alice" in v or "Bob" in v for v in diagnostics.values()), diagnostics  # nobody named

        # the operator with the key: a sealed request, a sealed reply (nothing readable in its plain fields)
        request = seal_request(Sealer(key, "operator"), GoToPerson.Request(name="Bob"), GOTO)
        reply = call(request)
        assert not reply.accepted and not reply.status and reply.sealed_response.ciphertext
        inner = open_response(Opener(key, "replies"), reply, GOTO, request)
        assert inner.accepted and inner.status.startswith("goal for 'Bob'"), inner.status
        n = len(goals)
        assert spin_until(executor, lambda: goals_for(BOB_Y, n), 30.0), [_person_y(g) for g in goals[n:]]
        assert spin_until(executor, lambda: "goal for 'Bob'" in opened[-1], 30.0), opened[-3:]
        # replayed by the keyless peer who overheard it: refused (the robot is not sent back and forth)
        reply = call(request)
        assert not reply.accepted and "replayed" in reply.status and not reply.sealed_response.ciphertext

        # face-reid-goto --send: without the key refused (exit 1); with it Alice again (exit 0)
        def cli(*args: str) -> subprocess.Popen[str]:
            return subprocess.Popen([sys.executable, "-m", "face_reid_master.ros.goto_node", *args,
                                     "--timeout-s", "60"], cwd=REPO_ROOT, env=procs.ros_env(ros_domain_id),
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

        def finished(proc: subprocess.Popen[str]) -> tuple[int, str, str]:
            done = spin_until(executor, lambda: proc.poll() is not None, 120.0)  # the tracks go on meanwhile
            if not done:
                proc.kill()
            out, err = proc.communicate()
            assert done, (out, err)
            return proc.returncode, out, err

        code, out, err = finished(cli("--send", "Bob"))
        assert code == 1 and "must be sealed" in err, (code, out, err)
        # a keyless rogue server on the same service answers too ("accepted"): the client passes it over and
        # takes the goto's sealed reply (asked again until the rogue heard one: discovery on a loaded machine)
        rogue_calls = [0]

        def rogue(request: Any, response: Any) -> Any:
            rogue_calls[0] += 1
            response.accepted, response.status = True, "goal for 'Mallory'"
            return response

        rogue_server = peer.create_service(GoToPerson, f"{GOTO}/go_to", rogue)
        for _ in range(5):
            code, out, err = finished(cli("--send", "Alice", "--key", str(key_path)))
            assert code == 0 and f"{GOTO}: goal for 'Alice'" in out and "Mallory" not in out, (code, out, err)
            if rogue_calls[0]:
                break
        assert rogue_calls[0], "the rogue server never heard a request"
        peer.destroy_service(rogue_server)
        n = len(goals)
        assert spin_until(executor, lambda: goals_for(ALICE_Y, n), 30.0), [_person_y(g) for g in goals[n:]]
        # a late reader with the key: the latched sealed status names the target
        code, out, err = finished(cli("--status", "--key", str(key_path)))
        assert code == 0 and "goal for 'Alice'" in out, (code, out, err)

        # and the keyless --send (a copy the client sent again while only the rogue had answered: a replay)
        assert spin_until(executor, lambda: int(diagnostics.get("go_to_refused", 0)) >= 5, 30.0), diagnostics
        assert not plain_status and not peer.get_publishers_info_by_topic(f"{GOTO}/status")
        assert not status.refused, status.refused
        assert goto.poll() is None, logs()
    finally:
        executor.shutdown()
        peer.destroy_node()
        procs.stop(goto)
    log = (tmp_path / "goto.log").read_text()
    assert log.count("secured: no /face_reid_goto/target topic") == 1, log[-3000:]


def test_the_client_drives_an_unsecured_goto_in_clear(ros_domain_id: int, ros_context, tmp_path: Path) -> None:
    """Without --key face-reid-goto --send / --status use an unsecured goto's plain ~/go_to and ~/status."""
    goto = procs.start(["-m", "face_reid_master.ros.goto_node", "--ros-args", "-p", "names_service:=''"],
                       ros_domain_id, tmp_path / "goto.log")
    ctx = ros_context()
    peer = Node("peer", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    tracks_pub = peer.create_publisher(NamedTrackArray, "/tracks_named", 10)
    k = [0]

    def publish_tracks() -> None:
        k[0] += 1
        tracks_pub.publish(_tracks(k[0]))

    peer.create_timer(0.1, publish_tracks)
    lines: list[str] = []
    StatusReader(peer, lines.append, "", GOTO)

    def cli(*args: str) -> tuple[int, str, str]:
        proc = subprocess.Popen([sys.executable, "-m", "face_reid_master.ros.goto_node", *args, "--timeout-s", "60"],
                                cwd=REPO_ROOT, env=procs.ros_env(ros_domain_id), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        done = spin_until(executor, lambda: proc.poll() is not None, 120.0)
        if not done:
            proc.kill()
        out, err = proc.communicate()
        assert done, (out, err)
        return proc.returncode, out, err

    try:
        assert spin_until(executor, lambda: any(s.startswith("no target") for s in lines), START_S), (
            lines, (tmp_path / "goto.log").read_text()[-3000:])
        code, out, err = cli("--send", "Bob")
        assert code == 0 and f"{GOTO}: goal for 'Bob'" in out, (code, out, err)
        code, out, err = cli("--send", "Nobody")
        assert code == 1 and "not accepted: refused 'Nobody': unknown name" in err, (code, out, err)
        assert spin_until(executor, lambda: "refused 'Nobody'" in lines[-1], 30.0), lines[-3:]
        code, out, err = cli("--status")
        assert code == 0 and "refused 'Nobody': unknown name" in out, (code, out, err)
        assert goto.poll() is None
    finally:
        executor.shutdown()
        peer.destroy_node()
        procs.stop(goto)


# ------------------------------------------------------------------------------------------ in-process
def test_a_secured_goto_reseals_its_latched_status_and_names_nobody_on_diagnostics(ros_context,
                                                                                   tmp_path: Path) -> None:
    """A reader opens only a recent seal: the secured goto seals its unchanged status again (a late reader of the
    latched topic gets a fresh one); the target and the status lines are not among its /diagnostics values."""
    from face_reid_master.ros import goto_node

    key_path = write_network_key(tmp_path / "network.key")
    ctx = ros_context(["--ros-args", "-p", f"network_key_path:={key_path}", "-p", "names_service:=''"])
    node = goto_node.GotoNode("Alice", context=ctx)
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert node.status_pub.msg_type is Sealed and node.status_pub.topic_name == f"{GOTO}/status_sealed"
        assert not [s for s in node.subscriptions if s.topic_name == f"{GOTO}/target"]
        sent: list[Any] = []
        node.status_pub.publish = sent.append
        node._reseal_status()  # just sealed at activation: not yet
        assert not sent
        node._status_sealed_s -= goto_node._STATUS_RESEAL_S
        node._reseal_status()
        assert len(sent) == 1 and sent[0].sender_id == GOTO
        opener = Opener(load_network_key(key_path), goto_node.STATUS_PURPOSE)
        from face_reid_camera.common.ros.sealed import open_message

        assert open_message(opener, sent[0], String).data == node._last_status
        assert "Alice" in node._last_status
        values = node.diagnostics(node.now_s()).values
        assert "target" not in values and "status" not in values and values["go_to_refused"] == "0", values
    finally:
        node.destroy_node()
