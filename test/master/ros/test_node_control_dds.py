"""Who can control a running node (real processes, real DDS): a peer without the network key can neither walk
a secured master's or camera's lifecycle nor read or set their parameters; a holder of the key can, with
face-reid-state; a shutdown transition ends the process. An unsecured node keeps the standard services and
says at start-up that they are open."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import REPO_ROOT, spin_until
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState as StdChangeState
from lifecycle_msgs.srv import GetState
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import (
    DescribeParameters,
    GetParameters,
    GetParameterTypes,
    ListParameters,
    SetParameters,
    SetParametersAtomically,
)
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from face_reid_camera.common.sealing import Sealer, load_network_key, write_network_key

pytestmark = [pytest.mark.ros, pytest.mark.slow]

MASTER, CAMERA = "/face_reid_master", "/cam_a/face_reid_camera"
LIFECYCLE_SERVICES = ("change_state", "get_state", "get_available_states", "get_available_transitions",
                      "get_transition_graph")
PARAMETER_SERVICES = ("get_parameters", "set_parameters", "set_parameters_atomically", "list_parameters",
                      "describe_parameters", "get_parameter_types")
N_FACES = 4
START_S = 180.0  # a loaded machine: the camera loads its models, three processes share two cores


def _store_faces(db: Path) -> list[int]:
    """N_FACES unnamed faces, last seen an hour ago (a retention_unnamed_s of 1 s would delete them all)."""
    from face_reid_master.identity.records import LearnedFace
    from face_reid_master.storage.face_store import FaceStore

    rng = np.random.default_rng(0)
    old = time.time() - 3600.0
    with FaceStore(db, embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        store.save_faces([LearnedFace(i, rng.normal(size=(2, 128)).astype(np.float32), None, old, old, 3)
                          for i in range(1, N_FACES + 1)])
        return [f.face_id for f in store.list_faces()]


def _services(peer: Node, fqn: str) -> set[str]:
    ns, name = fqn.rsplit("/", 1)
    try:
        return {s for s, _ in peer.get_service_names_and_types_by_node(name, ns or "/")}
    except Exception:  # the node is not discovered yet
        return set()


def _subscriptions(peer: Node, fqn: str) -> set[str]:
    ns, name = fqn.rsplit("/", 1)
    try:
        return {s for s, _ in peer.get_subscriber_names_and_types_by_node(name, ns or "/")}
    except Exception:
        return set()


def _call(executor: Any, client: Any, request: Any, timeout_s: float = 60.0) -> Any:
    future = client.call_async(request)
    assert spin_until(executor, future.done, timeout_s), f"{client.srv_name} did not answer"
    return future.result()


def _attack(executor: Any, peer: Node, fqn: str) -> list[str]:
    """Every standard lifecycle transition (by label and by id) and every parameter get / set a peer without the
    key can try on ``fqn``, in the order that would do the most harm (retention_unnamed_s 1 s is set when the
    node is unconfigured, read by the next configure); what answered."""
    answered: list[str] = []
    offered = _services(peer, fqn)

    def ready(name: str, srv_type: Any) -> Any:
        client = peer.create_client(srv_type, f"{fqn}/{name}")
        return client if f"{fqn}/{name}" in offered and spin_until(executor, client.service_is_ready, 10.0) else None

    change = ready("change_state", StdChangeState)
    get_state = ready("get_state", GetState)
    setp = ready("set_parameters", SetParameters)
    atomic = ready("set_parameters_atomically", SetParametersAtomically)
    retention = [Parameter(name="retention_unnamed_s", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                                             double_value=1.0))]
    for name, srv_type, request in (
        ("get_parameters", GetParameters, GetParameters.Request(names=["db_path", "network_key_path"])),
        ("list_parameters", ListParameters, ListParameters.Request()),
        ("describe_parameters", DescribeParameters, DescribeParameters.Request(names=["db_path"])),
        ("get_parameter_types", GetParameterTypes, GetParameterTypes.Request(names=["db_path"])),
    ):
        client = ready(name, srv_type)
        if client is not None:
            answered.append(f"{name}: {_call(executor, client, request)}"[:200])
    if get_state is not None:
        answered.append(f"get_state: {_call(executor, get_state, GetState.Request()).current_state.label}")
    for label in ("deactivate", "cleanup", "set", "configure", "activate"):
        if label == "set":
            for client, request in ((setp, SetParameters.Request(parameters=retention)),
                                    (atomic, SetParametersAtomically.Request(parameters=retention))):
                if client is not None:
                    answered.append(f"{client.srv_name}: {_call(executor, client, request)}"[:200])
        elif change is not None:
            ok = _call(executor, change, StdChangeState.Request(transition=Transition(label=label))).success
            answered.append(f"change_state {label}: {ok}")
    if change is not None:
        for tid in (Transition.TRANSITION_DEACTIVATE, Transition.TRANSITION_CLEANUP, Transition.TRANSITION_CONFIGURE,
                    Transition.TRANSITION_ACTIVATE, Transition.TRANSITION_ACTIVE_SHUTDOWN,
                    Transition.TRANSITION_INACTIVE_SHUTDOWN, Transition.TRANSITION_UNCONFIGURED_SHUTDOWN):
            ok = _call(executor, change, StdChangeState.Request(transition=Transition(id=tid))).success
            answered.append(f"change_state id {tid}: {ok}")
    return answered


def _state_cli(domain_id: int, *args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "face_reid_camera.tools.state", *args], cwd=REPO_ROOT,
                          env=procs.ros_env(domain_id), capture_output=True, text=True, timeout=timeout_s)


def _sealed_state(executor: Any, peer: Node, sealer: Sealer | None, fqn: str, transition: str) -> Any:
    """A ChangeState request (sealed with ``sealer``, or plain) to ``fqn``/change_state_sealed; its reply."""
    from face_reid_camera.common.ros.sealed import seal_request
    from face_reid_msgs.srv import ChangeState

    client = peer.create_client(ChangeState, f"{fqn}/change_state_sealed")
    assert spin_until(executor, client.service_is_ready, 60.0)
    request = ChangeState.Request(transition=transition)
    return _call(executor, client, seal_request(sealer, request) if sealer is not None else request)


def test_a_peer_without_the_key_controls_nothing_and_the_operator_with_it_does(ros_domain_id: int, ros_context,
                                                                               tmp_path: Path) -> None:
    key_path = write_network_key(tmp_path / "network.key")
    key = load_network_key(key_path)
    stranger_key = load_network_key(write_network_key(tmp_path / "stranger.key"))
    db = tmp_path / "faces.db"
    stored = _store_faces(db)
    master = procs.start(["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={db}",
                          "-p", "embedding_space:=dlib_resnet_v1", "-p", f"network_key_path:={key_path}",
                          "-p", "body_appearance_tracking:=false"], ros_domain_id, tmp_path / "master.log")
    camera = procs.start(["-m", "face_reid_camera.ros.node", "--ros-args", "-r", "__ns:=/cam_a",
                          "-p", "camera_id:=cam_a", "-p", f"network_key_path:={key_path}"],
                         ros_domain_id, tmp_path / "camera.log")
    ctx = ros_context()
    peer = Node("peer", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    from face_reid_msgs.srv import ListFaces

    logs = lambda: {p.name: p.read_text()[-3000:] for p in tmp_path.glob("*.log")}  # noqa: E731
    try:
        # barriers: what each node creates once configured / active (after any service of its constructor)
        assert spin_until(executor, lambda: f"{MASTER}/list_faces" in _services(peer, MASTER), START_S), logs()
        assert spin_until(executor, lambda: "/cam_a/color/image_raw" in _subscriptions(peer, CAMERA), START_S), logs()
        list_faces = peer.create_client(ListFaces, f"{MASTER}/list_faces")
        assert spin_until(executor, list_faces.service_is_ready, 60.0)
        assert sorted(_call(executor, list_faces, ListFaces.Request()).face_ids) == stored

        # the keyless peer tries everything on both nodes
        answered = {fqn: _attack(executor, peer, fqn) for fqn in (MASTER, CAMERA)}
        assert answered == {MASTER: [], CAMERA: []}
        for fqn in (MASTER, CAMERA):
            open_ones = {f"{fqn}/{s}" for s in (*LIFECYCLE_SERVICES, *PARAMETER_SERVICES)} & _services(peer, fqn)
            assert not open_ones, open_ones
            assert f"{fqn}/change_state_sealed" in _services(peer, fqn)
            # the sealed service: a plain request, one sealed with another key, a replay are all refused
            reply = _sealed_state(executor, peer, None, fqn, "shutdown")
            assert not reply.success and "must be sealed" in reply.message and reply.state == "active"
            reply = _sealed_state(executor, peer, Sealer(stranger_key, "stranger"), fqn, "deactivate")
            assert not reply.success and "network's key" in reply.message and reply.state == "active"
        # nothing changed: both still active, every face still there
        operator = Sealer(key, "operator")
        for fqn in (MASTER, CAMERA):
            reply = _sealed_state(executor, peer, operator, fqn, "get")
            assert reply.success and reply.state == "active", reply
        assert sorted(_call(executor, list_faces, ListFaces.Request()).face_ids) == stored

        # the operator with the key: face-reid-state walks the master through a full reconfigure
        for transition, state in (("deactivate", "inactive"), ("cleanup", "unconfigured"),
                                  ("configure", "inactive"), ("activate", "active")):
            done = _state_cli(ros_domain_id, MASTER, transition, "--key", str(key_path))
            assert done.returncode == 0 and f"(state {state})" in done.stdout, (done.stdout, done.stderr)
        refused = _state_cli(ros_domain_id, MASTER, "activate", "--key", str(key_path))
        assert refused.returncode == 1 and "cannot activate from active" in refused.stderr, refused.stderr
        keyless = _state_cli(ros_domain_id, MASTER, "deactivate", "--timeout-s", "5")
        assert keyless.returncode == 5, (keyless.stdout, keyless.stderr)  # no standard service to call
        # parameters unchanged: the reconfigure read retention_unnamed_s 0 again (no face to delete, no warning)
        assert spin_until(executor, list_faces.service_is_ready, 60.0)
        assert sorted(_call(executor, list_faces, ListFaces.Request()).face_ids) == stored
        assert "retention_unnamed_s" not in (tmp_path / "master.log").read_text()
        # a replayed operator request is refused too
        from face_reid_camera.common.ros.sealed import seal_request
        from face_reid_msgs.srv import ChangeState

        captured = seal_request(Sealer(key, "operator2"), ChangeState.Request(transition="deactivate"))
        client = peer.create_client(ChangeState, f"{CAMERA}/change_state_sealed")
        assert _call(executor, client, captured).success
        reply = _call(executor, client, captured)
        assert not reply.success and "replayed" in reply.message and reply.state == "inactive"

        # shutdown ends the process (exit status 0), it does not leave a finalized node behind
        done = _state_cli(ros_domain_id, CAMERA, "shutdown", "--key", str(key_path))
        assert done.returncode == 0 and "(state finalized)" in done.stdout, (done.stdout, done.stderr)
        assert camera.wait(timeout=60) == 0, logs()
    finally:
        executor.shutdown()
        peer.destroy_node()
        for proc in (camera, master):
            procs.stop(proc)
    from face_reid_master.storage.face_store import FaceStore

    with FaceStore(db, read_only=True, embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        assert sorted(f.face_id for f in store.list_faces()) == stored


def test_an_unsecured_camera_keeps_the_standard_services_and_warns(ros_domain_id: int, ros_context,
                                                                   tmp_path: Path) -> None:
    camera = procs.start(["-m", "face_reid_camera.ros.node", "--ros-args", "-r", "__ns:=/cam_a",
                          "-p", "camera_id:=cam_a"], ros_domain_id, tmp_path / "camera.log")
    ctx = ros_context()
    peer = Node("peer", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    try:
        get_state = peer.create_client(GetState, f"{CAMERA}/get_state")
        getp = peer.create_client(GetParameters, f"{CAMERA}/get_parameters")
        assert spin_until(executor, lambda: get_state.service_is_ready() and getp.service_is_ready(), START_S)
        assert spin_until(executor, lambda: _call(executor, get_state, GetState.Request()).current_state.label
                          == "active", START_S)
        reply = _call(executor, getp, GetParameters.Request(names=["camera_id"]))
        assert [v.string_value for v in reply.values] == ["cam_a"]
        warning = "UNSECURED: no network_key_path: the lifecycle services (/cam_a/face_reid_camera/change_state"
        assert warning in (tmp_path / "camera.log").read_text()
        done = _state_cli(ros_domain_id, CAMERA, "deactivate")  # no key: the standard service
        assert done.returncode == 0 and "(state inactive)" in done.stdout, (done.stdout, done.stderr)
        assert _call(executor, get_state, GetState.Request()).current_state.label == "inactive"
        change = peer.create_client(StdChangeState, f"{CAMERA}/change_state")
        assert _call(executor, change, StdChangeState.Request(transition=Transition(label="shutdown"))).success
        assert camera.wait(timeout=60) == 0  # the standard shutdown ends the process too
    finally:
        executor.shutdown()
        peer.destroy_node()
        procs.stop(camera)


@pytest.mark.parametrize("module,cls,extra", [
    ("face_reid_master.ros.node", "MasterNode", ["-p", "body_appearance_tracking:=false"]),
    ("face_reid_camera.ros.node", "CameraNode", ["-p", "detect_faces:=false"]),
    ("face_reid_master.ros.map_node", "MapNode", []),
    ("face_reid_master.ros.goto_node", "GotoNode", []),
])
def test_every_node_with_a_key_offers_only_the_sealed_control(ros_context, tmp_path: Path, module: str, cls: str,
                                                              extra: list[str]) -> None:
    import importlib

    key_path = write_network_key(tmp_path / "network.key")
    for secured in (True, False):
        key = ["-p", f"network_key_path:={key_path}"] if secured else []
        ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", *key, *extra])
        node = getattr(importlib.import_module(module), cls)(context=ctx)
        try:
            names = {s.srv_name.rsplit("/", 1)[-1] for s in node.services}
            standard = set(LIFECYCLE_SERVICES) | set(PARAMETER_SERVICES)
            if secured:
                assert not names & standard and "change_state_sealed" in names and node.secured, names
            else:
                assert standard <= names and "change_state_sealed" not in names and not node.secured, names
        finally:
            node.destroy_node()
