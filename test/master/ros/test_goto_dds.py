"""face-reid-goto end to end over DDS: simulated camera -> master -> ``face-reid-goto Alice`` -> /goal_pose.

Alice walks along y = 0 (world), leaves every view until her track is deleted and comes back walking the other
way along y = -1.5; Bob walks by once. The goals must follow Alice (the person they face, one stand-off away,
is where the master tracks her and on her path), change as she moves, go on after her return (a new track id,
the same name and face), and asking for a person who is gone or was never seen must give a refusal and no goal.
The goto node's handling of bad input is tested in-process (no master needed).
"""

from __future__ import annotations

import itertools
import json
import math
import re
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import spin_until
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from face_reid_master.robot.frames import PlanarTransform, save_world_to_map
from face_reid_master.ros.goto_node import GotoNode, target_from_args
from face_reid_msgs.msg import NamedTrack, NamedTrackArray
from face_reid_msgs.srv import GoToPerson

pytestmark = [pytest.mark.ros, pytest.mark.slow]

WORLD_TO_MAP = PlanarTransform(1.0, -2.0, math.radians(90.0))
STANDOFF_M = 1.0
# Alice's two visits (publisher seconds): along y = 0 walking +x, then along y = -1.5 walking -x
ALICE_1 = {"x": 0.0, "y": 0.0, "vx": 0.5, "identity": "alice", "photos": [0, 1, 2, 3, 4, 5]}
ALICE_2 = {"x": 2.5, "y": -1.5, "vx": -0.5, "identity": "alice", "photos": [6, 7, 8, 9]}
BOB = {"x": 0.0, "y": 3.0, "vx": 0.3, "identity": "bob", "photos": [0, 1, 2, 3]}
GOAL_LINE = re.compile(r"goal for 'Alice' \(track (\d+), face (\d+)\): x=(\S+) y=(\S+) yaw=\S+ deg, "
                       r"person at x=(\S+) y=(\S+) \(heading from (\w+)\)")


def _faces(tmp_path: Path) -> tuple[Path, Path]:
    """Synthetic dlib-space faces (a unit vector per person, a little noise per photo): the plan's embeddings
    and the master's gallery (other photos of the same people)."""
    rng = np.random.default_rng(3)
    centres = {k: (v := rng.normal(size=128)) / np.linalg.norm(v) for k in ("alice", "bob")}

    def photos(k: str, n: int) -> np.ndarray:
        rows = centres[k] + rng.normal(0.0, 0.01, (n, 128))
        return (rows / np.linalg.norm(rows, axis=1, keepdims=True)).astype(np.float32)

    plan_faces, gallery = tmp_path / "faces.npz", tmp_path / "gallery.npz"
    np.savez(plan_faces, alice=photos("alice", 10), bob=photos("bob", 4))
    np.savez(gallery, Alice=photos("alice", 3), Bob=photos("bob", 3))
    return plan_faces, gallery


def _on_path(world_xy: np.ndarray) -> float:
    """Distance of a world point from Alice's ground-truth path (either visit's segment)."""
    def seg(a: np.ndarray, b: np.ndarray) -> float:
        t = float(np.clip(np.dot(world_xy - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0))
        return float(np.linalg.norm(world_xy - (a + t * (b - a))))

    return min(seg(np.array([0.0, 0.0]), np.array([2.0, 0.0])), seg(np.array([2.5, -1.5]), np.array([0.75, -1.5])))


def test_goals_follow_alice_through_leave_and_return_and_refuse_who_is_not_tracked(
        ros_domain_id: int, ros_context, tmp_path: Path) -> None:
    plan_faces, gallery = _faces(tmp_path)
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"rate_hz": 10, "embeddings": str(plan_faces), "segments": [
        {"t0": 0.0, "t1": 4.0, "people": [ALICE_1]},
        {"t0": 0.0, "t1": 3.0, "people": [BOB]},
        {"t0": 6.5, "t1": 10.0, "people": [ALICE_2]},
    ]}))
    transform_file = tmp_path / "world_to_map.yaml"
    save_world_to_map(transform_file, WORLD_TO_MAP, map_frame="map")

    ctx = ros_context()
    from rclpy.node import Node

    node = Node("goto_test", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    goals: list[tuple[float, PoseStamped]] = []
    statuses: list[str] = []
    alice_seen: list[tuple[float, np.ndarray]] = []  # (received, world xy) of every Alice track published
    tracks_msgs = [0]

    def on_tracks(msg: NamedTrackArray) -> None:
        tracks_msgs[0] += 1
        now = time.monotonic()
        alice_seen.extend((now, np.array([t.position.x, t.position.y])) for t in msg.tracks if t.name == "Alice")

    latched = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    reliable = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(PoseStamped, "/goal_pose", lambda m: goals.append((time.monotonic(), m)), reliable)
    node.create_subscription(String, "/face_reid_goto/status", lambda m: statuses.append(m.data), latched)
    node.create_subscription(NamedTrackArray, "/tracks_named", on_tracks, reliable)
    go_to = node.create_client(GoToPerson, "/face_reid_goto/go_to")

    master_args = ["-m", "face_reid_master.ros.node", "--ros-args"]
    for p in (f"db_path:={tmp_path / 'faces.db'}", f"gallery_path:={gallery}", "embedding_space:=dlib_resnet_v1",
              "min_face_features_for_name:=3", "tracker.lost_after_s:=0.5", "tracker.delete_after_s:=1.0",
              "topic_discovery_period_s:=0.5"):
        master_args += ["-p", p]
    master = procs.start(master_args, ros_domain_id, tmp_path / "master.log")
    goto = procs.start(["-m", "face_reid_master.ros.goto_node", "Alice", "--ros-args", "-p",
                        f"world_to_map_path:={transform_file}", "-p", "names_refresh_period_s:=1.0"],
                       ros_domain_id, tmp_path / "goto.log")
    camera = None

    def logs() -> str:
        return "\n".join(f"--- {p.name}:\n{p.read_text()[-3000:]}" for p in sorted(tmp_path.glob("*.log")))

    def call(name: str) -> GoToPerson.Response:
        future = go_to.call_async(GoToPerson.Request(name=name))
        assert spin_until(executor, future.done, 20.0), logs()
        return future.result()

    try:
        # before anyone is seen, Alice cannot be gone to (an unknown name until the master's names arrive, then a
        # predefined person not tracked)
        assert spin_until(executor, lambda: any("refused 'Alice': unknown name" in s or "refused 'Alice': not tracked"
                                                in s for s in statuses), 60.0), (statuses, logs())
        assert spin_until(executor, lambda: tracks_msgs[0] > 0 and go_to.service_is_ready(), 30.0), logs()
        camera = procs.start([str(procs.PROCS / "publish_camera_frames.py"), "--camera-id", "cam_a", "--topic",
                              "/cam_a/face_reid/frames", "--plan", str(plan), "--wait-s", "60"],
                             ros_domain_id, tmp_path / "camera.log")
        assert spin_until(executor, lambda: camera.poll() is not None, 90.0), logs()
        assert camera.returncode == 0, logs()
        seen = tracks_msgs[0]
        assert spin_until(executor, lambda: tracks_msgs[0] >= seen + 3, 10.0), logs()  # the last ones arrived

        # who is gone (Bob left long ago) or was never seen: refused, and no goal follows
        n_goals = len(goals)
        reply = call("  bob ")
        assert not reply.accepted and reply.status == "refused 'bob': not tracked", reply.status
        reply = call("Nobody")
        assert not reply.accepted and reply.status == "refused 'Nobody': unknown name", reply.status
        seen = tracks_msgs[0]
        assert spin_until(executor, lambda: tracks_msgs[0] >= seen + 5, 10.0), logs()
        assert len(goals) == n_goals
        assert goto.poll() is None and master.poll() is None, logs()
    finally:
        for p in (camera, goto, master):
            if p is not None:
                procs.stop(p)
        executor.shutdown()
        node.destroy_node()

    # ---- the goals
    assert len(goals) >= 6, (statuses, logs())
    assert all(m.header.frame_id == "map" for _, m in goals)
    to_world = WORLD_TO_MAP.inverse()
    errors_tracked, errors_path = [], []
    for received, m in goals:
        yaw = 2.0 * math.atan2(m.pose.orientation.z, m.pose.orientation.w)
        person_map = np.array([m.pose.position.x + STANDOFF_M * math.cos(yaw),
                               m.pose.position.y + STANDOFF_M * math.sin(yaw)])
        person = to_world.apply(person_map)
        # the tracks message a goal came from may reach this test just after the goal (two topics)
        recent = [xy for t, xy in alice_seen if received - 1.0 <= t <= received + 0.5]
        assert recent, "a goal while Alice was not published"
        errors_tracked.append(min(float(np.linalg.norm(person - xy)) for xy in recent))
        errors_path.append(_on_path(person))
    # the person each goal faces is where the master tracks Alice (the message it came from is among those
    # around it) and on her true path (the tracker's error, coasting past her last detection); reported with -s
    print(f"goals {len(goals)}: faced person vs Alice's track max {max(errors_tracked):.3f} m; vs her path "
          f"median {np.median(errors_path):.3f} max {max(errors_path):.3f} m")
    assert max(errors_tracked) < 0.02, errors_tracked
    assert max(errors_path) < 0.35, errors_path

    # ---- the status lines: two visits (two tracks, one face), goals changing as she walks, headings
    lines = [GOAL_LINE.search(s) for s in statuses]
    visits = [(int(g[1]), int(g[2]), float(g[5]), float(g[6]), g[7]) for g in lines if g]
    track_ids = list(dict.fromkeys(v[0] for v in visits))
    assert len(track_ids) == 2, statuses
    assert len({v[1] for v in visits}) == 1 and visits[0][1] != 0, visits
    between = statuses[max(i for i, s in enumerate(statuses) if f"track {track_ids[0]}," in s):]
    assert any("refused 'Alice': only a lost track" in s or "refused 'Alice': not tracked" in s for s in between)
    for tid, path_y in zip(track_ids, (0.0, -1.5), strict=True):
        world = [to_world.apply(np.array([v[2], v[3]])) for v in visits if v[0] == tid]
        assert len(world) >= 3, visits  # re-issued as she walked
        assert all(abs(p[1] - path_y) < 0.35 for p in world)
        steps = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(world)]
        assert min(steps) > 0.0 and sum(steps) > 1.0, steps
        # walking: she is faced from one stand-off ahead of her (world +x on the first visit, -x on the return)
        headings = [v for v in visits if v[0] == tid and v[4] == "velocity"]
        assert headings, visits
    for _, m in goals[-2:]:  # the return: walking world -x, so the goal faces world +x = map +y
        yaw = 2.0 * math.atan2(m.pose.orientation.z, m.pose.orientation.w)
        assert abs(math.remainder(yaw - math.pi / 2, 2 * math.pi)) < math.radians(30), yaw


# ------------------------------------------------------------------------------------------ in-process
def _track(tid: int, name: str, x: float, y: float, state: int = NamedTrack.STATE_CONFIRMED) -> NamedTrack:
    t = NamedTrack(track_id=tid, face_id=tid, name=name, identity_confidence=0.9, state=state)
    t.position.x, t.position.y = x, y
    return t


def test_goto_node_survives_bad_input_and_refuses_hostile_names(ros_context) -> None:
    ctx = ros_context(["--ros-args", "-p", "names_service:=''", "-p", "min_goal_interval_s:=0.0"])
    node = GotoNode("Alice", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert node.map_frame == "map"
        # nothing heard from the master yet: waiting, not "unknown name"
        assert node._last_status == "waiting for /tracks_named: nothing received yet (target 'Alice')"
        published: list[PoseStamped] = []
        node.goal_pub.publish = published.append  # what the node would send
        msg = NamedTrackArray()
        msg.header.frame_id = "world"
        msg.tracks = [_track(1, "Alice", float("nan"), 0.0), _track(2, "x" * 100_000, 1.0, 1.0),
                      _track(3, "Al\x1b[2Jice", 1.0, 1.0), _track(4, "Alice", 2.0, 0.0, state=7)]
        node._on_tracks(msg)
        assert node.rejected == {"malformed_track": 1} and not published
        assert node._last_status == "refused 'Alice': unknown name"
        msg.tracks.append(_track(5, "alice", 3.0, 1.0))
        node._on_tracks(msg)
        assert len(published) == 1 and published[0].header.frame_id == "map"
        assert (published[0].pose.position.x, published[0].pose.position.y) == pytest.approx((4.0, 1.0))
        for hostile in ("y" * 100_000, "Bob\n[INFO] fake log line"):
            response = node._on_go_to(GoToPerson.Request(name=hostile), GoToPerson.Response())
            assert not response.accepted and response.status.startswith("refused: invalid name")
            assert len(response.status) < 200 and "\n" not in response.status
        assert node.core.target == "Alice"  # refused names do not change the target
        node._on_target(String(data="  "))
        assert node._last_status.startswith("no target: no goals; waiting for a name on the /face_reid_goto/go_to")
        node._on_robot_pose(PoseStamped())  # frame '' is not the map frame
        assert node.rejected["robot_pose"] == 1
        robot = PoseStamped()
        robot.header.frame_id, robot.pose.position.x, robot.pose.position.y = "map", 3.0, 5.0
        node._on_robot_pose(robot)
        node._on_target(String(data="Alice"))  # standing at (3, 1): faced from the robot's side
        assert (published[-1].pose.position.x, published[-1].pose.position.y) == pytest.approx((3.0, 2.0))
        node._on_target(String(data="  "))
        report = node.diagnostics(node.now_s())
        assert report.values["rejected_malformed_track"] == "2" and report.values["goals"] == "2"
    finally:
        executor.shutdown()
        node.destroy_node()


def test_without_a_target_it_says_once_what_it_waits_for(ros_context, capfd: pytest.CaptureFixture[str]) -> None:
    """Started without a name it publishes no goal and logs, once, where a name is taken from."""
    ctx = ros_context(["--ros-args", "-p", "names_service:=''"])
    node = GotoNode(None, context=ctx)
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        waiting = ("no target: no goals; waiting for a name on the /face_reid_goto/go_to service "
                   "(face_reid_msgs/srv/GoToPerson) or the /face_reid_goto/target topic (std_msgs/msg/String), or "
                   "start with face-reid-goto NAME")
        assert node._last_status == waiting
        msg = NamedTrackArray()
        msg.header.frame_id = "world"
        msg.tracks = [_track(1, "Alice", 1.0, 0.0)]
        node._on_tracks(msg)
        node._on_tracks(msg)
        assert node.counts["goals"] == 0 and node._last_status == waiting
        assert capfd.readouterr().err.count("waiting for a name") == 1
    finally:
        node.destroy_node()


def test_name_on_the_command_line() -> None:
    assert target_from_args(["face-reid-goto", "Alice", "--ros-args", "-p", "x:=1"]) == "Alice"
    assert target_from_args(["face-reid-goto", "Mary", "Ann"]) == "Mary Ann"
    assert target_from_args(["face-reid-goto", "--ros-args", "-p", "target_name:=Bob"]) is None
