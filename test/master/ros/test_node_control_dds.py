"""Who can control a running node (real processes, real DDS): a peer without the network key can neither walk
a secured master's or camera's lifecycle nor read or set their parameters; a holder of the key can, with
face-reid-state; a shutdown transition ends the process. An unsecured node keeps the standard services and
says at start-up that they are open."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
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
RESEND_S = 5.0  # a read or refused request not answered within this is sent again (see _answered)


def _store_faces(db: Path, names: dict[int, str] | None = None) -> list[int]:
    """N_FACES faces (unnamed but for ``names``: face id -> name), last seen an hour ago (a retention_unnamed_s of
    1 s would delete the unnamed ones)."""
    from face_reid_master.identity.records import LearnedFace
    from face_reid_master.storage.face_store import FaceStore

    rng = np.random.default_rng(0)
    old = time.time() - 3600.0
    names = names or {}
    with FaceStore(db, embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        store.save_faces([LearnedFace(i, rng.normal(size=(2, 128)).astype(np.float32), names.get(i), old, old, 3)
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
    """One request, one reply: only on a client that had a reply already (:func:`_answered`), or for a request
    whose reply may be lost without harm (the attack: what answers at all)."""
    future = client.call_async(request)
    assert spin_until(executor, future.done, timeout_s), f"{client.srv_name} did not answer"
    return future.result()


def _answered(executor: Any, client: Any, make_request: Callable[[], Any], timeout_s: float = 120.0) -> tuple[Any, Any]:
    """A request of ``make_request()`` (made again for each send: a sealed request is taken once), sent again every
    RESEND_S until one is answered; (that request, its reply). A barrier as well: a server sends a reply only to a
    client reader it has matched (rmw_fastrtps waits 100 ms for that, then drops the reply), and service_is_ready()
    says only that the client matched the server, so on a loaded machine a first reply can be lost; once a reply
    came, the client is matched both ways. Only for requests that may be done twice (reads, refusals, probes)."""
    sent: list[tuple[Any, Any]] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        request = make_request()
        sent.append((request, client.call_async(request)))
        if spin_until(executor, lambda: any(f.done() for _, f in sent), min(RESEND_S, deadline - time.monotonic())):
            return next((r, f.result()) for r, f in sent if f.done())
    raise AssertionError(f"{client.srv_name} did not answer {len(sent)} requests in {timeout_s:g} s")


def _barrier(executor: Any, condition: Callable[[], bool], procs_by_name: dict[str, Any], logs: Callable[[], Any],
             timeout_s: float = START_S) -> None:
    """Spin until ``condition()``; fails at once (with the logs) when one of the processes has exited."""
    assert spin_until(executor, lambda: condition() or any(p.poll() is not None for p in procs_by_name.values()),
                      timeout_s), logs()
    exited = {name: p.poll() for name, p in procs_by_name.items() if p.poll() is not None}
    assert not exited, (exited, logs())


def _only_one(peer: Node, fqn: str) -> None:
    """``fqn`` names one node on this test's domain: a second one (a process left over by another test or run)
    would answer the graph queries and the calls in its place."""
    ns, name = fqn.rsplit("/", 1)
    found = [n for n in peer.get_node_names_and_namespaces() if n == (name, ns or "/")]
    assert len(found) == 1, f"{len(found)} nodes named {fqn} on this domain"


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


def _operator_transition(domain_id: int, fqn: str, transition: str, key_path: Path) -> str:
    """face-reid-state ``fqn`` ``transition`` with the key; its output. The tool sends its request once: when the
    node's reply is lost (see :func:`_answered`: the tool is a new client each time) the tool ends with status 5
    although the node did the transition, so then the tool's ``get`` (read-only, asked until it answers) says
    where the node is."""
    done = _state_cli(domain_id, fqn, transition, "--key", str(key_path), "--timeout-s", "30")
    for _ in range(5):
        if done.returncode != 5:
            break
        done = _state_cli(domain_id, fqn, "get", "--key", str(key_path), "--timeout-s", "30")
    assert done.returncode == 0, (transition, done.stdout, done.stderr)
    return done.stdout


def _sealed_state(executor: Any, peer: Node, sealer: Sealer | None, fqn: str, transition: str,
                  key: bytes | None = None) -> Any:
    """A ChangeState request (sealed with ``sealer`` for ``fqn``, or plain) to ``fqn``/change_state_sealed; its
    reply (opened with ``key`` when given: the node's reply sealed for the request)."""
    from face_reid_camera.common.ros.sealed import open_response, seal_request
    from face_reid_camera.common.sealing import Opener
    from face_reid_msgs.srv import ChangeState

    client = peer.create_client(ChangeState, f"{fqn}/change_state_sealed")
    assert spin_until(executor, client.service_is_ready, 60.0)

    def make(transition: str = transition) -> Any:
        request = ChangeState.Request(transition=transition)
        return seal_request(sealer, request, fqn) if sealer is not None else request

    if transition == "get" or key is None:  # a read, or a request the node refuses: sent until answered
        request, reply = _answered(executor, client, make)
    else:  # a transition is asked once, on a client that had a reply ("get") already
        _answered(executor, client, lambda: make("get"))
        request = make()
        reply = _call(executor, client, request)
    return open_response(Opener(key, "replies"), reply, fqn, request) if key is not None else reply


def _list_faces(executor: Any, client: Any, key: bytes | None) -> Any:
    """The master's ~/list_faces reply: a keyless request, or one sealed with ``key`` (its sealed reply opened)."""
    from face_reid_msgs.srv import ListFaces

    if key is None:
        return _answered(executor, client, ListFaces.Request)[1]
    from face_reid_camera.common.ros.sealed import open_response, seal_request
    from face_reid_camera.common.sealing import Opener

    request, reply = _answered(executor, client, lambda: seal_request(Sealer(key, f"lister-{time.time_ns()}"),
                                                                      ListFaces.Request(), MASTER))
    return open_response(Opener(key, "replies"), reply, MASTER, request)


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
    running = {"master": master, "camera": camera}
    try:
        # barriers: what each node creates once configured / active (after any service of its constructor); a
        # node that exited fails at once, and each name must be this test's node alone
        _barrier(executor, lambda: f"{MASTER}/list_faces" in _services(peer, MASTER), running, logs)
        _barrier(executor, lambda: "/cam_a/color/image_raw" in _subscriptions(peer, CAMERA), running, logs)
        for fqn in (MASTER, CAMERA):
            _only_one(peer, fqn)
        list_faces = peer.create_client(ListFaces, f"{MASTER}/list_faces")
        assert spin_until(executor, list_faces.service_is_ready, 60.0)
        assert sorted(_list_faces(executor, list_faces, key).face_ids) == stored

        # the keyless peer tries everything on both nodes
        answered = {fqn: _attack(executor, peer, fqn) for fqn in (MASTER, CAMERA)}
        assert answered == {MASTER: [], CAMERA: []}
        for fqn in (MASTER, CAMERA):
            open_ones = {f"{fqn}/{s}" for s in (*LIFECYCLE_SERVICES, *PARAMETER_SERVICES)} & _services(peer, fqn)
            assert not open_ones, open_ones
            assert f"{fqn}/change_state_sealed" in _services(peer, fqn)
            # the sealed service: a plain request, one sealed with another key, a replay are all refused
            reply = _sealed_state(executor, peer, None, fqn, "shutdown")
            assert not reply.success and "must be sealed" in reply.message and not reply.state
            reply = _sealed_state(executor, peer, Sealer(stranger_key, "stranger"), fqn, "deactivate")
            assert not reply.success and "network's key" in reply.message and not reply.state
        # nothing changed: both still active, every face still there
        operator = Sealer(key, "operator")
        for fqn in (MASTER, CAMERA):
            reply = _sealed_state(executor, peer, operator, fqn, "get", key)
            assert reply.success and reply.state == "active", reply
        assert sorted(_list_faces(executor, list_faces, key).face_ids) == stored

        # the operator with the key: face-reid-state walks the master through a full reconfigure
        for transition, state in (("deactivate", "inactive"), ("cleanup", "unconfigured"),
                                  ("configure", "inactive"), ("activate", "active")):
            out = _operator_transition(ros_domain_id, MASTER, transition, key_path)
            assert f"state {state}" in out, (transition, out)
        refused = _state_cli(ros_domain_id, MASTER, "activate", "--key", str(key_path))
        assert refused.returncode == 1 and "cannot activate from active" in refused.stderr, refused.stderr
        keyless = _state_cli(ros_domain_id, MASTER, "deactivate", "--timeout-s", "5")
        assert keyless.returncode == 5, (keyless.stdout, keyless.stderr)  # no standard service to call
        # parameters unchanged: the reconfigure read retention_unnamed_s 0 again (no face to delete, no warning)
        assert spin_until(executor, list_faces.service_is_ready, 60.0)
        assert sorted(_list_faces(executor, list_faces, key).face_ids) == stored
        assert "retention_unnamed_s" not in (tmp_path / "master.log").read_text()
        # a replayed operator request is refused too
        from face_reid_camera.common.ros.sealed import open_response, seal_request
        from face_reid_camera.common.sealing import Opener
        from face_reid_msgs.srv import ChangeState

        captured = seal_request(Sealer(key, "operator2"), ChangeState.Request(transition="deactivate"), CAMERA)
        client = peer.create_client(ChangeState, f"{CAMERA}/change_state_sealed")
        assert spin_until(executor, client.service_is_ready, 60.0)
        probe = Sealer(key, "probe")  # the barrier: this client had a reply, so the next ones are not lost
        _answered(executor, client, lambda: seal_request(probe, ChangeState.Request(transition="get"), CAMERA))
        assert open_response(Opener(key, "replies"), _call(executor, client, captured), CAMERA, captured).success
        reply = _call(executor, client, captured)
        assert not reply.success and "replayed" in reply.message and not reply.state

        # shutdown ends the process (exit status 0), it does not leave a finalized node behind
        done = _state_cli(ros_domain_id, CAMERA, "shutdown", "--key", str(key_path), "--timeout-s", "60")
        assert camera.wait(timeout=90) == 0, logs()  # the process ended: the shutdown was done
        assert done.returncode in (0, 5), (done.stdout, done.stderr)  # 5: the reply was lost (see _answered)
        assert done.returncode == 5 or "(state finalized)" in done.stdout, (done.stdout, done.stderr)
    finally:
        executor.shutdown()
        peer.destroy_node()
        for proc in (camera, master):
            procs.stop(proc)
    from face_reid_master.storage.face_store import FaceStore

    with FaceStore(db, read_only=True, embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        assert sorted(f.face_id for f in store.list_faces()) == stored


def _diagnostics_of(peer: Node) -> dict[str, dict[str, str]]:
    """The newest /diagnostics values per hardware id (the master: its name; a camera: its camera id), kept
    up to date by a subscription of ``peer``."""
    from diagnostic_msgs.msg import DiagnosticArray

    latest: dict[str, dict[str, str]] = {}

    def keep(msg: Any) -> None:
        for status in msg.status:
            latest[status.hardware_id] = {kv.key: kv.value for kv in status.values}

    peer.create_subscription(DiagnosticArray, "/diagnostics", keep, 50)
    return latest


def test_a_sealed_request_is_for_its_node_and_only_the_nodes_sealed_reply_is_believed(
        ros_domain_id: int, ros_context, tmp_path: Path) -> None:
    """The attacks of a keyless peer on the sealed control and listing: a deactivate sealed for the camera, sent
    to the master; a rogue server on the master's control service answering the operator first; polling
    list_faces for names and last-seen times. And the counts of all that on /diagnostics."""
    from face_reid_camera.common.ros.sealed import seal_request
    from face_reid_msgs.srv import ChangeState, ListFaces

    key_path = write_network_key(tmp_path / "network.key")
    key = load_network_key(key_path)
    db = tmp_path / "faces.db"
    stored = _store_faces(db, {1: "Alice"})
    master = procs.start(["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={db}",
                          "-p", "embedding_space:=dlib_resnet_v1", "-p", f"network_key_path:={key_path}",
                          "-p", "body_appearance_tracking:=false"], ros_domain_id, tmp_path / "master.log")
    camera = procs.start(["-m", "face_reid_camera.ros.node", "--ros-args", "-r", "__ns:=/cam_a",
                          "-p", "camera_id:=cam_a", "-p", "detect_faces:=false", "-p", f"network_key_path:={key_path}"],
                         ros_domain_id, tmp_path / "camera.log")
    ctx = ros_context()
    peer = Node("peer", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    diagnostics = _diagnostics_of(peer)
    logs = lambda: {p.name: p.read_text()[-3000:] for p in tmp_path.glob("*.log")}  # noqa: E731

    def faces_cli(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "face_reid_master.tools.faces_cli", "--master", MASTER,
                               "--timeout-s", "60", *args], cwd=REPO_ROOT, env=procs.ros_env(ros_domain_id),
                              capture_output=True, text=True, timeout=120)

    try:
        assert spin_until(executor, lambda: f"{MASTER}/list_faces" in _services(peer, MASTER), START_S), logs()
        assert spin_until(executor, lambda: "/cam_a/color/image_raw" in _subscriptions(peer, CAMERA), START_S), logs()
        list_faces = peer.create_client(ListFaces, f"{MASTER}/list_faces")
        assert spin_until(executor, list_faces.service_is_ready, 60.0)

        # list_faces: nothing for a keyless peer (no names, no last-seen times); the names for a key holder
        keyless = _list_faces(executor, list_faces, None)
        assert (list(keyless.face_ids), list(keyless.names), list(keyless.last_seen_s)) == ([], [], [])
        held = _list_faces(executor, list_faces, key)
        assert sorted(held.face_ids) == stored and dict(zip(held.face_ids, held.names, strict=True))[1] == "Alice"
        run = faces_cli("list")
        assert run.returncode == 0 and "0 face(s)" in run.stdout and "Alice" not in run.stdout, run
        run = faces_cli("--key", str(key_path), "list")
        assert run.returncode == 0 and f"{N_FACES} face(s)" in run.stdout and "Alice" in run.stdout, run

        # a deactivate sealed for the camera, captured and sent to the master: refused, saying for whom it was
        captured = seal_request(Sealer(key, "operator"), ChangeState.Request(transition="deactivate"), CAMERA)
        to_master = peer.create_client(ChangeState, f"{MASTER}/change_state_sealed")
        assert spin_until(executor, to_master.service_is_ready, 60.0)
        reply = _call(executor, to_master, captured)
        assert not reply.success and f"sealed for '{CAMERA}', not for this node ({MASTER})" in reply.message, reply
        assert _sealed_state(executor, peer, Sealer(key, "operator2"), MASTER, "get", key).state == "active"
        # the camera counts its sealed control requests and refusals on /diagnostics
        assert _sealed_state(executor, peer, Sealer(key, "operator3"), CAMERA, "get", key).state == "active"
        assert not _sealed_state(executor, peer, None, CAMERA, "deactivate").success
        assert spin_until(executor, lambda: diagnostics.get("cam_a", {}).get("control_requests") == "2"
                          and diagnostics["cam_a"].get("control_refused") == "1", 30.0), diagnostics.get("cam_a")

        # a keyless rogue server on the master's control service, answering at once with a refusal: the tool
        # passes its reply over and reports the master's own (the tool's discovery decides whether the rogue hears
        # the request: asked again until it did)
        for transition in ("deactivate", "cleanup"):
            assert _sealed_state(executor, peer, Sealer(key, f"op-{transition}"), MASTER, transition, key).success
        rogue_calls: list[str] = []

        def rogue(request: Any, response: Any) -> Any:
            rogue_calls.append(request.sealed_request.sender_id)
            response.success, response.message, response.state = False, "refused: ROGUE WORDS", "unconfigured"
            return response

        rogue_srv = peer.create_service(ChangeState, f"{MASTER}/change_state_sealed", rogue)

        def state_tool(transition: str) -> tuple[int, str, str]:
            tool = subprocess.Popen([sys.executable, "-m", "face_reid_camera.tools.state", MASTER, transition,
                                     "--key", str(key_path), "--timeout-s", "90"], cwd=REPO_ROOT,
                                    env=procs.ros_env(ros_domain_id), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True)
            assert spin_until(executor, lambda: tool.poll() is not None, 150.0), logs()
            out, err = tool.communicate()
            assert "ROGUE" not in out + err, (out, err)
            return tool.returncode, out, err

        deadline = time.monotonic() + 240.0  # a loaded machine discovers slowly: until the rogue heard one
        while not rogue_calls and time.monotonic() < deadline:
            code, out, err = state_tool("get")
            assert code == 0 and "state unconfigured" in out, (out, err)
        assert rogue_calls, "the rogue never heard the tool's request"
        code, out, err = state_tool("configure")
        assert code == 0 and "configure: done (state inactive)" in out, (out, err)
        peer.destroy_service(rogue_srv)
        assert _sealed_state(executor, peer, Sealer(key, "op-activate"), MASTER, "activate", key).success

        # the master's counts: 2 list_faces refused (the peer's and the tool's keyless), 2 answered; control
        # requests: the camera's captured one (refused), get, deactivate, cleanup, the tool's, activate
        def master_counts() -> bool:
            values = diagnostics.get(MASTER, {})
            return (values.get("list_faces_calls"), values.get("list_faces_refused")) == ("4", "2") and int(
                values.get("control_requests", 0)) >= 6 and int(values.get("control_refused", 0)) >= 1

        assert spin_until(executor, master_counts, 30.0), diagnostics.get(MASTER)
    finally:
        executor.shutdown()
        peer.destroy_node()
        for proc in (camera, master):
            procs.stop(proc)


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
