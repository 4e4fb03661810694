"""The master's optional /people (people_msgs) and REP-155 (hri_msgs) outputs, across processes over DDS.

people_msgs and hri_msgs are not on PyPI: the module fixture builds the minimal stand-ins of
test/data/interfaces (same package, message and field names as upstream) with colcon, once, and runs the master
and a listener with that install on their paths. A camera process shows a predefined person; /people must carry
her name and position, /humans/persons/tracked her person id and its face_id sub-topic her face id. Without the
packages the master warns once and carries on (in-process).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT, colcon_build, spin_until
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from face_reid_master.demo.children import spawn

pytestmark = [pytest.mark.ros, pytest.mark.slow]

INTERFACES = REPO_ROOT / "test" / "data" / "interfaces"
BUILD_SECONDS: list[float] = []  # how long the colcon build took (reported in the assertion messages)

# The listener: /people, /humans/persons/tracked and the per-person sub-topics of the first identified person;
# prints one JSON line once it has all of them (or what it has at the timeout).
LISTENER = r"""
import json, sys, time
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from people_msgs.msg import People
from hri_msgs.msg import IdsList
from std_msgs.msg import Bool, Float32, String

rclpy.init()
node = rclpy.create_node("people_listener")
got = {"people": None, "tracked": None, "known": None, "sub": {}}
latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

def on_people(msg):
    named = [p for p in msg.people if not p.name.startswith(("track_", "face_"))]
    if named:
        got["people"] = {"frame_id": msg.header.frame_id, "people": [
            {"name": p.name, "x": p.position.x, "y": p.position.y, "reliability": p.reliability,
             "tags": dict(zip(p.tagnames, p.tags))} for p in msg.people]}

def on_tracked(msg):
    ids = [i for i in msg.ids if i.startswith("face")]
    if not ids:
        return
    first, got["tracked"] = got["tracked"] is None, list(msg.ids)
    if first:
        for sub, kind in (("face_id", String), ("name", String), ("anonymous", Bool),
                          ("location_confidence", Float32)):
            node.create_subscription(kind, f"/humans/persons/{ids[0]}/{sub}",
                                     lambda m, s=sub: got["sub"].__setitem__(s, m.data), latched)

def on_known(msg):
    got["known"] = list(msg.ids)

node.create_subscription(People, "/people", on_people, 10)
node.create_subscription(IdsList, "/humans/persons/tracked", on_tracked, 10)
node.create_subscription(IdsList, "/humans/persons/known", on_known, latched)
deadline = time.monotonic() + float(sys.argv[1])
while time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
    if got["people"] and got["tracked"] and got["known"] and len(got["sub"]) == 4:
        break
print(json.dumps(got), flush=True)
"""


@pytest.fixture(scope="module")
def interface_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """people_msgs and hri_msgs built with colcon (one invocation for this module); the environment variables a
    process needs to use them (Python path, their libraries, the ament index)."""
    ws = tmp_path_factory.mktemp("people_interfaces")
    for pkg in ("people_msgs", "hri_msgs"):
        shutil.copytree(INTERFACES / pkg, ws / "src" / pkg)
    t0 = time.monotonic()
    colcon_build(ws)
    BUILD_SECONDS.append(time.monotonic() - t0)
    install = ws / "install"
    pkgs = ("people_msgs", "hri_msgs")
    sites = [str(p) for pkg in pkgs for p in (install / pkg / "lib").glob("python*/site-packages")]
    assert len(sites) == 2, sites

    def joined(name: str, *first: str) -> str:
        return os.pathsep.join([*first, os.environ.get(name, "")]).rstrip(os.pathsep)

    return {
        "PYTHONPATH": joined("PYTHONPATH", *sites),
        "LD_LIBRARY_PATH": joined("LD_LIBRARY_PATH", *(str(install / pkg / "lib") for pkg in pkgs)),
        "AMENT_PREFIX_PATH": joined("AMENT_PREFIX_PATH", *(str(install / pkg) for pkg in pkgs)),
    }


def _env(domain_id: int, extra: dict[str, str]) -> dict[str, str]:
    env = procs.ros_env(domain_id)
    env.update(extra)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT), extra["PYTHONPATH"]])
    return env


def _unit_rows(seed: int, n: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    center = rng.normal(size=128)
    rows = center + 0.02 * rng.normal(size=(n, 128))
    return (rows / np.linalg.norm(rows, axis=1, keepdims=True)).astype(np.float32)


def test_people_and_rep155_topics_carry_a_predefined_person(ros_domain_id: int, tmp_path: Path,
                                                            interface_env: dict[str, str]) -> None:
    gallery = tmp_path / "gallery.npz"
    np.savez(gallery, Alice=_unit_rows(3))  # the predefined person and what the camera sends for her
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"rate_hz": 10, "embeddings": str(gallery), "segments": [
        {"t0": 0, "t1": 6, "people": [{"x": 1.5, "y": -0.5, "identity": "Alice", "photos": [0, 1, 2]},
                                      {"x": -2.0, "y": 1.0}]}]}))  # and someone whose face is never seen
    env = _env(ros_domain_id, interface_env)
    args = ["-m", "face_reid_master.ros.node", "--ros-args"]
    for param in ("topic_discovery_period_s:=0.5", "embedding_space:=dlib_resnet_v1", f"gallery_path:={gallery}",
                  f"db_path:={tmp_path / 'faces.db'}", "publish_people:=true", "publish_hri:=true"):
        args += ["-p", param]
    with open(tmp_path / "master.log", "w") as master_log, open(tmp_path / "listener.log", "w") as listener_log:
        master = spawn(args, env, stdout=subprocess.DEVNULL, stderr=master_log, cwd=REPO_ROOT)
        listener = spawn(["-c", LISTENER, "90"], env, stdout=subprocess.PIPE, stderr=listener_log, cwd=REPO_ROOT)
    camera = procs.start([str(procs.PROCS / "publish_camera_frames.py"), "--camera-id", "cam_a", "--topic",
                          "/cam_a/face_reid/frames", "--plan", str(plan), "--wait-s", "60"],
                         ros_domain_id, tmp_path / "camera.log")
    try:
        got = procs.json_line(listener, 120)
    finally:
        procs.stop(camera)
        procs.stop(listener)
        procs.stop(master)
    logs = {p.name: p.read_text()[-2000:] for p in tmp_path.glob("*.log")}
    why = f"build {BUILD_SECONDS} s; got {got}; logs {logs}"
    assert got["people"] is not None and got["tracked"] is not None, why
    assert got["people"]["frame_id"] == "world", why
    (alice,) = [p for p in got["people"]["people"] if p["name"] == "Alice"]
    assert alice["x"] == pytest.approx(1.5, abs=0.2) and alice["y"] == pytest.approx(-0.5, abs=0.2), why
    face_id = alice["tags"]["face_id"]
    assert int(face_id) > 0 and alice["tags"]["person_id"] == f"face{face_id}", why
    assert f"face{face_id}" in got["tracked"] and f"face{face_id}" in got["known"], why
    assert got["sub"] == {"face_id": face_id, "name": "Alice", "anonymous": False,
                          "location_confidence": pytest.approx(1.0)}, why
    assert "not installed" not in logs["master.log"], why
    (stranger,) = [p for p in got["people"]["people"] if p["name"].startswith("track_")]
    assert stranger["x"] == pytest.approx(-2.0, abs=0.2) and stranger["tags"]["face_id"] == "0", why
    assert f"anon{stranger['tags']['track_id']}" in got["tracked"], why  # an anonymous REP-155 person


class _Recorder:
    """A logger that keeps the warnings it passes on."""

    def __init__(self, logger: object) -> None:
        self.logger, self.warnings = logger, []

    def warning(self, message: str, **kwargs: object) -> object:
        self.warnings.append(message)
        return self.logger.warning(message, **kwargs)

    def __getattr__(self, name: str) -> object:
        return getattr(self.logger, name)


def test_without_the_packages_the_master_warns_once_and_runs(ros_context, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    if importlib.util.find_spec("people_msgs") or importlib.util.find_spec("hri_msgs"):
        pytest.skip("people_msgs / hri_msgs are installed in this environment")
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.node import Node

    from face_reid_master.records import CameraFrameRecord, PersonRecord
    from face_reid_master.ros.convert import frame_record_to_msg
    from face_reid_master.ros.node import MasterNode
    from face_reid_msgs.msg import NamedTrackArray

    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "camera_topic_regex:=''",
                       "-p", "check_stamps_against_clock:=false", "-p", "publish_people:=true",
                       "-p", "publish_hri:=true"])
    node = MasterNode(context=ctx)
    recorder = _Recorder(node.get_logger())
    monkeypatch.setattr(node, "get_logger", lambda: recorder)
    listener = Node("listener", context=ctx)
    received: list[NamedTrackArray] = []
    listener.create_subscription(NamedTrackArray, "/tracks_named", received.append, 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    executor.add_node(listener)
    try:
        ok = TransitionCallbackReturn.SUCCESS
        assert node.trigger_configure() == ok and node.trigger_activate() == ok
        mine = [w for w in recorder.warnings if "is set but" in w]
        assert len(mine) == 2, recorder.warnings
        assert mine[0].startswith("publish_people is set but people_msgs is not installed: /people not published")
        assert mine[1].startswith("publish_hri is set but hri_msgs is not installed")
        for k in range(5):
            person = PersonRecord(np.array([1.0, 2.0, 0.0]), 0.05, 1.7)
            stamp = 100.0 + 0.1 * k
            node._on_frame(frame_record_to_msg(CameraFrameRecord("cam_a", stamp, (person,)), stamp))
        assert spin_until(executor, lambda: any(m.tracks for m in received), 20.0)
        assert [w for w in recorder.warnings if "is set but" in w] == mine  # once, not per publish
        names = {name for name, _ in node.get_topic_names_and_types()}
        assert "/people" not in names and "/humans/persons/tracked" not in names
        assert node.trigger_deactivate() == ok
    finally:
        executor.shutdown()
        listener.destroy_node()
        node.destroy_node()


class _Pub:
    def __init__(self, topic: str) -> None:
        self.topic_name, self.sent = topic, []

    def publish(self, msg: object) -> None:
        self.sent.append(msg)


class _Node:
    """What PeopleTopics uses of a node, recording publishers."""

    def __init__(self) -> None:
        self.pubs: dict[str, _Pub] = {}
        self.destroyed: list[str] = []
        self.failures: list[str] = []

    def create_publisher(self, msg_type: object, topic: str, qos: object) -> _Pub:
        self.pubs[topic] = _Pub(topic)
        return self.pubs[topic]

    def destroy_publisher(self, pub: _Pub) -> None:
        self.destroyed.append(pub.topic_name)
        del self.pubs[pub.topic_name]

    def get_logger(self) -> _Node:
        return self

    def info(self, message: str) -> None:
        pass

    warning = info

    def log_throttled(self, key: str, message: str, total: int | None = None, warn: bool = False) -> None:
        self.failures.append(message)


def test_person_topics_are_made_on_first_use_latched_and_dropped(monkeypatch: pytest.MonkeyPatch) -> None:
    """The helper's bookkeeping (no DDS): per-person publishers made when a person appears, values sent only when
    they change, the anonymous id aliased to the identified one, publishers destroyed once the person is gone."""
    import types
    from types import SimpleNamespace

    from face_reid_master.records import STATE_CONFIRMED, NamedTrackRecord
    from face_reid_master.ros import params as master_params
    from face_reid_master.ros.people_topics import PeopleTopics

    def header() -> SimpleNamespace:
        return SimpleNamespace(stamp=None, frame_id="")

    class Point(SimpleNamespace):
        def __init__(self) -> None:
            super().__init__(x=0.0, y=0.0, z=0.0)

    fakes = {
        "people_msgs.msg": types.SimpleNamespace(
            People=lambda: SimpleNamespace(header=header(), people=[]),
            Person=lambda: SimpleNamespace(name="", position=Point(), velocity=Point(), reliability=0.0,
                                           tagnames=[], tags=[])),
        "hri_msgs.msg": types.SimpleNamespace(IdsList=lambda: SimpleNamespace(header=header(), ids=[])),
    }
    for name, module in fakes.items():
        monkeypatch.setitem(sys.modules, name, module)
    values = {**master_params.defaults(), "publish_people": True, "publish_hri": True, "hri_forget_after_s": 1.0}
    node = _Node()
    topics = PeopleTopics(node, values)
    topics.activate()
    assert set(node.pubs) == {"/people", "/humans/persons/tracked", "/humans/persons/known"}

    def track(face_id: int, name: str = "") -> NamedTrackRecord:
        return NamedTrackRecord(7, face_id, name, 0.9, 3, np.array([1.0, 2.0]), np.zeros(2), np.eye(4), 1.7,
                                STATE_CONFIRMED, 0.0, 1.0)

    topics.publish([track(0)], None, 0.0)
    assert {"/humans/persons/anon7/anonymous", "/humans/persons/anon7/location_confidence"} <= set(node.pubs)
    assert node.pubs["/people"].sent[-1].people[0].name == "track_7"
    topics.publish([track(2, "Bob")], None, 0.5)
    topics.publish([track(2, "Bob")], None, 0.6)
    assert [m.data for m in node.pubs["/humans/persons/anon7/alias"].sent] == ["face2"]
    assert [m.data for m in node.pubs["/humans/persons/face2/face_id"].sent] == ["2"]  # latched: sent once
    assert [m.data for m in node.pubs["/humans/persons/face2/name"].sent] == ["Bob"]
    assert node.pubs["/humans/persons/known"].sent[-1].ids == ["anon7", "face2"]
    assert [m.ids for m in node.pubs["/humans/persons/tracked"].sent] == [["anon7"], ["face2"], ["face2"]]
    topics.publish([], None, 3.0)
    assert not [t for t in node.pubs if t.count("/") > 3] and topics.person_topics == 0
    assert "/humans/persons/face2/face_id" in node.destroyed and node.pubs["/humans/persons/known"].sent[-1].ids == []
    topics.publish(None, None, 4.0)  # type: ignore[arg-type]  # a failure is logged, never raised
    assert node.failures and "people topics failed" in node.failures[0]
    topics.deactivate()
    assert node.pubs == {}
