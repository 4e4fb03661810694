"""The master node in-process: lifecycle, services, rejections, the publish-rate cap (sim time), /diagnostics.

Real rclpy (one context per test, loopback-only discovery); frames are handed to the node's subscription
callback directly, so every step is deterministic. The multi-process proof over DDS (two camera processes,
leave and return, kill -9) is test_master_node_dds.py.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import call_handler, spin_until, start_up_output

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.serialization import serialize_message
from rclpy.time import Time

from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.ros import params as master_params
from face_reid_master.ros.convert import frame_record_to_msg
from face_reid_master.ros.node import MasterNode
from face_reid_msgs.msg import NamedTrackArray
from face_reid_msgs.srv import AddPerson, ForgetFace, ListFaces

REPO = Path(__file__).resolve().parents[3]
OK = TransitionCallbackReturn.SUCCESS
CAM = "/cam_a/face_reid/frames"


def _master(ros_context, tmp_path: Path, *extra: str) -> MasterNode:
    """A master node on a temporary database, comparing dlib embeddings (what these tests send) unless set, its
    face table updated every cycle (identity_period_s 0) unless set."""
    if not any(p.startswith("embedding_space:=") for p in extra):
        extra = ("embedding_space:=dlib_resnet_v1", *extra)
    if not any(p.startswith("identity_period_s:=") for p in extra):
        extra = ("identity_period_s:=0.0", *extra)
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", f"camera_topics:=[{CAM}]",
                       "-p", "camera_topic_regex:=''", *[a for p in extra for a in ("-p", p)]])
    return MasterNode(context=ctx)


def _unit(seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=128).astype(np.float32)
    return v / np.linalg.norm(v)


def _frame(stamp_s: float, camera: str = "cam_a", emb: np.ndarray | None = None, frame_id: str = "world"):
    person = PersonRecord(np.array([1.0, 2.0, 0.0]), 0.05, 1.7, emb, 0.9 if emb is not None else 0.0,
                          0.8 if emb is not None else 0.0)
    return frame_record_to_msg(CameraFrameRecord(camera, stamp_s, (person,), frame_id), stamp_s)


def _feed(node: MasterNode, msg) -> None:
    """One frame through the subscription callback (which runs a cycle)."""
    node._on_frame(msg)


def test_lifecycle_subscribes_only_while_active_and_keeps_faces(ros_context, tmp_path: Path) -> None:
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false")
    try:
        assert node.core is None and not list(node.subscriptions)
        assert node.trigger_configure() == OK
        assert node.core is not None and node.store is not None and not list(node.subscriptions)
        assert node.tracks_pub is None
        assert node.trigger_activate() == OK
        assert {s.topic_name for s in node.subscriptions} == {CAM}
        assert node.tracks_pub.topic_name == "/tracks_named"
        for k in range(6):  # one person with the same face: a track and (after 3 observations) a face
            _feed(node, _frame(100.0 + 0.1 * k, emb=_unit(1)))
        assert node.core.identity.face_ids() == [1]
        assert node.trigger_deactivate() == OK
        assert not list(node.subscriptions) and node.tracks_pub is None
        assert node.trigger_cleanup() == OK  # saves every face and closes the database
        assert node.core is None and node.store is None
        assert node.trigger_configure() == OK  # reconfigure: the face comes back from the database
        assert node.core.identity.face_ids() == [1]
        assert node.trigger_shutdown() == OK
    finally:
        node.destroy_node()


def test_corrupt_database_is_set_aside_and_a_fresh_one_started(ros_context, tmp_path: Path) -> None:
    db = tmp_path / "faces.db"
    db.write_bytes(b"this is not a database" * 100)
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        backups = list(tmp_path.glob("faces.db.corrupt-*"))
        assert len(backups) == 1 and backups[0].read_bytes().startswith(b"this is not a database")
        for k in range(6):
            _feed(node, _frame(100.0 + 0.1 * k, emb=_unit(5)))
        assert node.core.identity.face_ids() == [1] and [f.face_id for f in node.store.load_faces()] == [1]
    finally:
        node.destroy_node()


def test_parameters_are_read_on_configure_and_locked_while_configured(ros_context, tmp_path: Path) -> None:
    from rclpy.parameter import Parameter

    node = _master(ros_context, tmp_path)
    try:
        assert node.set_parameters([Parameter("min_observations", value=5)])[0].successful
        assert node.trigger_configure() == OK and node.core.config.min_observations == 5
        result = node.set_parameters([Parameter("min_observations", value=3)])[0]
        assert not result.successful and "read on configure" in result.reason
        bad = node.set_parameters([Parameter("posterior_threshold", value=2.0)])[0]
        assert not bad.successful  # out of range, refused by the descriptor
    finally:
        node.destroy_node()


def _call(executor, node: Node, client, request):
    assert spin_until(executor, lambda: client.service_is_ready())
    future = client.call_async(request)
    assert spin_until(executor, future.done)
    return future.result()


def test_services_add_list_forget_and_refuse_hostile_requests(ros_context, tmp_path: Path) -> None:
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false", "admin_services:=true",
                   f"photo_root:={tmp_path}")
    client_node = Node("client", context=node.context)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    executor.add_node(client_node)
    add = client_node.create_client(AddPerson, "/face_reid_master/add_person")
    forget = client_node.create_client(ForgetFace, "/face_reid_master/forget_face")
    listing = client_node.create_client(ListFaces, "/face_reid_master/list_faces")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        alice = _unit(7)
        reply = _call(executor, node, add, AddPerson.Request(name="Alice", embeddings=np.tile(alice, 6).tolist()))
        assert reply.success and reply.num_embeddings == 6
        for req, why in (
            (AddPerson.Request(name="", embeddings=alice.tolist()), "name must not be empty"),
            (AddPerson.Request(name="Bob", embeddings=alice[:100].tolist()), "k x 128"),
            (AddPerson.Request(name="Bob", embeddings=[math.nan] * 128), ""),
            (AddPerson.Request(name="Bob", image_paths=[str(tmp_path / "missing.jpg")]), "missing.jpg"),
        ):
            reply = _call(executor, node, add, req)
            assert not reply.success and why in reply.message
        for k in range(8):  # Alice walks in and shows her face: a face, named from the gallery
            _feed(node, _frame(50.0 + 0.1 * k, emb=alice + 0.01 * _unit(100 + k)))
        faces = _call(executor, node, listing, ListFaces.Request())
        # the learned face, then the predefined person (face id 0: no face id is 0) with her 6 embeddings
        assert list(faces.face_ids) == [1, 0] and list(faces.names) == ["Alice", "Alice"]
        assert faces.num_features[0] >= 3 and faces.num_features[1] == 6
        assert not _call(executor, node, forget, ForgetFace.Request()).success  # neither id nor name
        assert not _call(executor, node, forget, ForgetFace.Request(face_id=99)).success
        # a restart (face-reid-up restarts the master on its own): Alice is still named, as a gallery person is
        assert node.trigger_deactivate() == OK and node.trigger_cleanup() == OK
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        assert node.core.people.names() == ["Alice"]  # before: 0 predefined people after a restart
        assert node.core.face_name(1) == "Alice"
        gone = _call(executor, node, forget, ForgetFace.Request(name="Alice"))
        assert gone.success and list(gone.forgotten_face_ids) == [1]
        assert list(_call(executor, node, listing, ListFaces.Request()).face_ids) == []
        assert node.store.load_faces() == [] and node.store.load_people() == {}  # deleted from disk too
        assert node.trigger_deactivate() == OK and node.trigger_cleanup() == OK
        assert node.trigger_configure() == OK and node.core.people.names() == []  # forgotten stays forgotten
    finally:
        executor.shutdown()
        client_node.destroy_node()
        node.destroy_node()


def test_admin_services_are_off_by_default(ros_context, tmp_path: Path) -> None:
    node = _master(ros_context, tmp_path)
    try:
        assert node.trigger_configure() == OK
        offered = {srv.srv_name for srv in node.services}
        assert "~/list_faces" in offered and not offered & {"~/add_person", "~/forget_face"}
    finally:
        node.destroy_node()


def test_add_person_survives_hostile_photo_paths_names_and_sizes(ros_context, tmp_path: Path) -> None:
    """Each of these crashed (cv2.error / allocation error: exit 1) or froze (FIFO) the master before
    photo_root and the request caps, or stored what it should not (a 1,000,000-character name)."""
    import os
    import shutil
    import threading

    from conftest import FACES_DIR

    root = tmp_path / "gallery"
    root.mkdir()
    photo = sorted((FACES_DIR / "deepface_id02").glob("*.jpg"))[0]
    shutil.copy(photo, root / "alice.jpg")
    with open(root / "huge.jpg", "wb") as f:
        f.truncate(2 * 2**30 + 1)  # 2 GB (sparse): np.fromfile + cv2.imdecode raised cv2.error
    with open(root / "sparse.jpg", "wb") as f:
        f.truncate(64 * 2**30)  # 64 GB: the allocation failed
    os.mkfifo(root / "fifo.jpg")  # froze the executor until someone wrote to it
    (root / "dir.jpg").mkdir()
    (root / "passwd.jpg").symlink_to("/etc/passwd")
    (root / "bomb.png").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + (50000).to_bytes(4, "big") * 2
                                    + b"\x08\x02\x00\x00\x00" + bytes(64))
    node = _master(ros_context, tmp_path, "admin_services:=true", f"photo_root:={root}", "max_photos_per_request:=8",
                   "max_embeddings_per_request:=4")
    alice = _unit(7)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        for req, why in (
            (AddPerson.Request(name="Eve", image_paths=["huge.jpg"]), "more than 20000000"),
            (AddPerson.Request(name="Eve", image_paths=["sparse.jpg"]), "more than 20000000"),
            (AddPerson.Request(name="Eve", image_paths=["fifo.jpg"]), "not a regular file"),
            (AddPerson.Request(name="Eve", image_paths=["/dev/zero"]), "outside the photo root"),
            (AddPerson.Request(name="Eve", image_paths=["dir.jpg"]), "not a regular file"),
            (AddPerson.Request(name="Eve", image_paths=["passwd.jpg"]), "outside the photo root"),
            (AddPerson.Request(name="Eve", image_paths=[str(photo)]), "outside the photo root"),
            (AddPerson.Request(name="Eve", image_paths=["bomb.png"]), "50000 x 50000 pixels"),
            (AddPerson.Request(name="Eve", image_paths=["alice.jpg"] * 9), "more than 8 photos"),
            (AddPerson.Request(name="Eve", embeddings=np.tile(alice, 5).tolist()), "more than 4 embeddings"),
            (AddPerson.Request(name="x" * 1_000_000, embeddings=alice.tolist()), "1000000 characters"),
            (AddPerson.Request(name="Eve\n    2  root", embeddings=alice.tolist()), "control characters"),
            (AddPerson.Request(name="\x1b[2JEve", embeddings=alice.tolist()), "control characters"),
        ):
            replies: list = []
            worker = threading.Thread(
                target=lambda r=req, out=replies: out.append(
                    call_handler(node.admin.add_person, r, AddPerson.Response())),
                daemon=True)
            worker.start()
            worker.join(30.0)
            assert replies, f"{why}: the service handler froze"
            assert not replies[0].success and why in replies[0].message, (why, replies[0].message[:300])
            assert len(replies[0].message) <= 1000
        assert node.core.people.names() == []  # nothing stored by any of them
        reply = call_handler(node.admin.add_person, AddPerson.Request(name="Alice", image_paths=["alice.jpg"]),
                             AddPerson.Response())
        assert reply.success and reply.num_embeddings == 1 and node.core.people.names() == ["Alice"]
        assert node.admin.refusals["add_person"] == 13 and node.admin.calls["add_person"] == 14
    finally:
        node.destroy_node()


def test_bad_frames_are_rejected_counted_and_reported(ros_context, tmp_path: Path) -> None:
    node = _master(ros_context, tmp_path, "known_camera_ids:=[cam_a]")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        now = node.now_s()
        _feed(node, _frame(now, camera="cam_zz"))  # unknown camera
        _feed(node, _frame(now, frame_id="map"))  # wrong world frame
        _feed(node, _frame(now - 3600.0))  # an hour old: skewed clock
        _feed(node, _frame(now + 3600.0))  # from the future
        _feed(node, _frame(now, emb=np.full(128, np.nan, np.float32)))  # accepted, embedding refused
        short = _frame(now)
        short.people[0].face_found = True
        short.people[0].embedding = [0.1] * 12
        _feed(node, short)  # accepted, embedding refused
        raw = serialize_message(_frame(now))  # what the camera subscription delivers: the CDR bytes
        _feed(node, raw)  # accepted
        _feed(node, raw[:-3])  # truncated
        _feed(node, b"\x00\x00\x00\x00" + b"\xff" * 40)  # big endian (read by rclpy), not a CameraFrame
        values = node.diagnostics(node.now_s()).values
        assert values["rejected_malformed"] == "2"
        assert values["rejected_unknown_camera"] == "1" and values["rejected_frame_id"] == "1"
        assert values["rejected_stale_stamp"] == "1" and values["rejected_future_stamp"] == "1"
        assert values["embeddings_rejected_nonfinite"] == "1" and values["embeddings_rejected_length"] == "1"
        assert values["frames_applied"] == "3" and values["tracks"] == "1"  # its 3 detections confirm a track
        assert node.core.identity.face_ids() == []
    finally:
        node.destroy_node()


def test_publish_rate_cap_on_the_node_clock(ros_context, tmp_path: Path) -> None:
    """30 frames/s for 2 s of sim time with the cap at 4 Hz: about 8 messages instead of 60."""

    def published(cap_hz: float) -> int:
        node = _master(ros_context, tmp_path / str(cap_hz), "use_sim_time:=true", f"max_publish_rate_hz:={cap_hz}",
                       "tick_rate_hz:=0.1", "check_stamps_against_clock:=false", "persist_faces:=false")
        try:
            assert node.trigger_configure() == OK and node.trigger_activate() == OK
            clock = node.get_clock()
            for k in range(60):
                t = 1000.0 + k / 30.0
                clock.set_ros_time_override(Time(seconds=t))
                _feed(node, _frame(t, camera="cam_a" if k % 2 else "cam_b"))
            return node.health.messages_published
        finally:
            node.destroy_node()

    assert published(0.0) == 60  # no cap: one message per frame
    capped = published(4.0)
    assert 7 <= capped <= 9, capped


def test_a_cycle_applies_its_frames_in_stamp_order_and_publishes_once(ros_context, tmp_path: Path) -> None:
    """Frames that arrived out of order (two cameras) are applied in stamp order, none refused as late, and
    the cycle publishes one message stamped with the newest frame."""
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false", "persist_faces:=false",
                   "tracker.max_detection_delay_s:=0.05")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        stamps = [10.0 + 0.1 * k for k in range(8)]
        for k, t in enumerate(reversed(stamps)):  # newest first: one by one, all but the first would be late
            node.receiver.receive(_frame(t, camera="cam_a" if k % 2 else "cam_b"), node.now_s())  # waiting together
        published = node.health.messages_published
        node._cycle(node.now_s())
        stats = node.core.stats
        assert stats.frames_applied == 8 and stats.frames_rejected_tracker_late == 0
        assert node.health.messages_published == published + 1
        assert len(node.core.tracks()) == 1  # one person seen 8 times, not 8 tracks
    finally:
        node.destroy_node()


def test_the_face_table_is_updated_at_most_once_per_identity_period(ros_context, tmp_path: Path) -> None:
    """Cycles within identity_period_s of the last identity update leave their frames' face evidence waiting
    (tracks move, no face yet); the next update after the period, the tick or a deactivation applies all of it."""
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false", "persist_faces:=false",
                   "identity_period_s:=1.0")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        _feed(node, _frame(100.0, emb=_unit(2)))  # the first cycle updates (none before it)
        for k in range(1, 6):
            _feed(node, _frame(100.0 + 0.1 * k, emb=_unit(2)))
        assert node.core.stats.frames_applied == 6 and len(node.core.tracks()) == 1
        assert node.core.identity.face_ids() == []  # 5 observations wait for the next update
        node._tick()
        assert node.core.identity.face_ids() == [1]
        node.schedule.identity_done -= 1.0  # the period has passed: the next cycle updates again
        _feed(node, _frame(100.6, emb=_unit(2)))
        assert not node.core.identity_pending
        _feed(node, _frame(100.7, emb=_unit(2)))  # within the period again: waits
        assert node.core.identity_pending
        assert node.trigger_deactivate() == OK
        assert not node.core.identity_pending
    finally:
        node.destroy_node()


def test_a_message_sooner_than_min_cycle_period_waits_for_its_cycle(ros_context, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A camera message that comes within min_cycle_period_s of the last cycle's start sleeps out the rest before
    its cycle (so that the messages arriving meanwhile join it); one after the period does not wait."""
    import face_reid_master.ros.node as node_module

    slept: list[float] = []
    real_sleep = time.sleep
    monkeypatch.setattr(node_module.time, "sleep", lambda s: (slept.append(s), real_sleep(s)))
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false", "persist_faces:=false",
                   "min_cycle_period_s:=0.1")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        _feed(node, _frame(10.0))
        assert slept == []  # no cycle before it
        node.schedule.cycle_began = time.monotonic()  # a cycle began just now
        _feed(node, _frame(10.1))
        assert len(slept) == 1 and 0.05 < slept[0] <= 0.1
        node.schedule.cycle_began -= 1.0  # long ago
        _feed(node, _frame(10.2))
        assert len(slept) == 1 and node.core.stats.frames_applied == 3
    finally:
        node.destroy_node()


def test_an_overloaded_cycle_drops_the_oldest_fairly_and_reports_it(ros_context, tmp_path: Path) -> None:
    """More frames than the cycle budget allows: the oldest are dropped (each camera keeps its newest),
    counted in the stats and /diagnostics, and what is applied is the newest."""
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false", "persist_faces:=false",
                   "cycle_budget_ms:=1.0")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        node.schedule.budget.mean_cost_ms = 0.25  # as measured on a slow host: 4 frames per 1 ms cycle
        for k in range(30):  # camera a sends 20 frames, camera b 10, interleaved, all waiting together
            node.receiver.receive(_frame(10.0 + 0.01 * k, camera="cam_b" if k % 3 == 2 else "cam_a"), node.now_s())
        node._cycle(node.now_s())
        assert node.frames_dropped_overload == 26 and node.core.stats.frames_applied == 4
        values = node.diagnostics(node.now_s()).values
        assert values["frames_dropped_overload"] == "26" and values["frames_in"] == "30"
        assert float(values["frames_dropped_overload_fraction"]) == pytest.approx(26 / 30, abs=1e-3)
        assert values["frames_dropped"] == "26"
        assert node.core.stats.frames_received == 4
        # fair: camera a (20 waiting) lost its 18 oldest, camera b (10) its 8 oldest; each applied its newest 2
        applied = node.core.admission._camera_frames
        assert {cam: len(times) for cam, times in applied.items()} == {"cam_a": 2, "cam_b": 2}
    finally:
        node.destroy_node()


def _master_with_probe(ros_context, tmp_path: Path) -> tuple[MasterNode, Node, SingleThreadedExecutor]:
    """A master (stamps not checked against the clock) and a probe node, both in one executor."""
    node = _master(ros_context, tmp_path, "check_stamps_against_clock:=false")
    probe = Node("probe", context=node.context)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    executor.add_node(probe)
    return node, probe, executor


def test_diagnostics_are_published_with_the_master_fields(ros_context, tmp_path: Path) -> None:
    node, probe, executor = _master_with_probe(ros_context, tmp_path)
    got: list[DiagnosticArray] = []
    tracks: list[NamedTrackArray] = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
    probe.create_subscription(NamedTrackArray, "/tracks_named", tracks.append, 10)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        for k in range(5):
            _feed(node, _frame(10.0 + 0.1 * k, emb=_unit(3)))
        assert spin_until(executor, lambda: got and got[-1].status[0].name == "face_reid_master"
                          and any(kv.key == "frames_in" and kv.value == "5" for kv in got[-1].status[0].values))
        values = {kv.key: kv.value for kv in got[-1].status[0].values}
        for key in ("frames_in", "frames_processed", "frames_dropped", "processing_time_p50_ms",
                    "processing_time_p95_ms", "people_per_frame", "faces_per_frame", "learned_faces", "tracks",
                    "publish_rate_hz", "rejected_total"):
            assert key in values, key
        assert values["frames_processed"] == "5" and values["learned_faces"] == "1" and values["tracks"] == "1"
        assert float(values["faces_per_frame"]) == 1.0
        assert spin_until(executor, lambda: tracks and tracks[-1].tracks and tracks[-1].tracks[0].face_id == 1)
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_lifecycle_and_parameter_services_answer_and_timers_survive_reactivation(ros_context, tmp_path: Path) -> None:
    """The node's own entity lists are not rclpy's: its lifecycle and parameter services are waited on (a
    ``ros2 lifecycle`` / ``ros2 param`` call is answered), each timer is waited on once, and a deactivate /
    activate keeps /diagnostics going (the node's timer list had been rclpy's: the services were dropped from
    the executor, every timer listed twice, and deactivating destroyed the diagnostics timer)."""
    from lifecycle_msgs.srv import GetState
    from rcl_interfaces.srv import ListParameters

    node, probe, executor = _master_with_probe(ros_context, tmp_path)
    got: list[DiagnosticArray] = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        timers = list(node.timers)
        assert len(timers) == len({id(t) for t in timers}) >= 4
        services = {s.srv_name.rsplit("/", 1)[-1] for s in node.services}  # waited on by the executor
        assert {"get_state", "change_state", "list_parameters", "set_parameters", "list_faces"} <= services
        for srv_type, name, check in ((GetState, "/face_reid_master/get_state", lambda r: r.current_state.label),
                                      (ListParameters, "/face_reid_master/list_parameters",
                                       lambda r: "identity_period_s" in r.result.names)):
            client = probe.create_client(srv_type, name)
            assert spin_until(executor, client.service_is_ready)
            future = client.call_async(srv_type.Request())
            assert spin_until(executor, future.done) and check(future.result()), name
        assert node.trigger_deactivate() == OK and node.trigger_activate() == OK
        assert len(list(node.timers)) == len(timers)
        got.clear()
        assert spin_until(executor, lambda: bool(got), timeout_s=10.0)  # diagnostics go on after reactivation
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


@pytest.mark.parametrize("override,expected", [
    ("posterior_threshold:=1.2", "parameter 'posterior_threshold' must be in [0.5, 0.999), got 1.2"),
    ("embedding_space:=dlib", "parameter 'embedding_space' must be one of"),
    ("tracker.max_tracks:=0", "parameter 'tracker.max_tracks' must be in [1, 100000], got 0"),
])
def test_bad_parameter_is_one_fatal_line(ros_domain_id: int, tmp_path: Path, override: str, expected: str) -> None:
    status, lines = start_up_output("face_reid_master.ros.node", "-p", override, "-p", f"db_path:={tmp_path / 'f.db'}")
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith("[face-reid-master] FATAL: cannot start: ") and expected in lines[0]


def test_every_parameter_has_a_range_or_choices_where_one_applies() -> None:
    for spec in master_params.TABLE.specs:
        if spec.kind in ("int", "float", "float_list"):
            assert spec.low is not None and spec.high is not None, spec.name
        assert len(spec.description) > 20, spec.name
    assert not set(master_params.EVALUATION_ONLY) & set(master_params.TABLE.names())
    assert master_params.master_config(master_params.defaults()).method == "bayes"


def test_config_yaml_gives_the_defaults() -> None:
    assert master_params.TABLE.load_yaml(REPO / "config" / "master.yaml") == master_params.defaults()
    assert master_params.master_config(master_params.defaults()) == master_params.MasterConfig()


def test_a_camera_whose_clock_is_behind_is_reported(ros_context, tmp_path: Path) -> None:
    """Frames of cam_b arrive 1.5 s after their stamp (its clock behind; still within max_stamp_age_s, so
    applied): /diagnostics warns and names it; cam_a, on time, is not named."""
    node = _master(ros_context, tmp_path, "persist_faces:=false")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        for _ in range(10):
            now = time.time()
            _feed(node, _frame(now, camera="cam_a"))
            _feed(node, _frame(now - 1.5, camera="cam_b"))
        report = node.diagnostics(node.now_s())
        assert report.values["cameras_clock_off"] == "1"
        assert float(report.values["clock_offset_ms_'cam_b'"]) == pytest.approx(1500.0, abs=100.0)
        assert "chrony" in report.message and "'cam_b'" in report.message and report.level == 1
    finally:
        node.destroy_node()


def test_a_camera_publishing_best_effort_is_named_as_unmatched(ros_context, tmp_path: Path) -> None:
    """The camera subscriptions carry no QoS-event handlers (cost per cycle): a publisher whose QoS cannot match
    the master's reliable subscription is found from the graph instead, said once, and cleared when matched."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from face_reid_msgs.msg import CameraFrame

    node = _master(ros_context, tmp_path, "persist_faces:=false")
    camera = Node("best_effort_camera", context=node.context)
    executor = SingleThreadedExecutor(context=node.context)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        assert all(len(sub.event_handlers) == 0 for sub in node.cameras.subscribed.values())
        executor.add_node(node)
        executor.add_node(camera)
        lossy = camera.create_publisher(CameraFrame, CAM,
                                        QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))

        def seen() -> bool:
            node.cameras.warn_unmatched()
            return node.diagnostics(node.now_s()).values["camera_topics_unmatched"] == "1"

        assert spin_until(executor, seen, 20.0)
        report = node.diagnostics(node.now_s())
        assert CAM in report.message and "reliable" in report.message and report.level == 1
        camera.destroy_publisher(lossy)
        camera.create_publisher(CameraFrame, CAM, QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE))

        def matched() -> bool:
            node.cameras.warn_unmatched()
            return node.diagnostics(node.now_s()).values["camera_topics_unmatched"] == "0"

        assert spin_until(executor, matched, 20.0)
    finally:
        executor.shutdown()
        camera.destroy_node()
        node.destroy_node()


def test_tracks_keep_coming_while_an_add_person_request_decodes_its_photos(ros_context, tmp_path: Path) -> None:
    """Photos are decoded on the admin worker: the executor goes on publishing /tracks_named meanwhile (before, a
    request of eight 81-megapixel PNGs left /tracks_named silent for 18 s). Photos beyond the request's pixel
    budget, or larger than a photo may be, are skipped with a reason."""
    import cv2
    from conftest import FACES_DIR

    from face_reid_master.ros import admin_services as admin_module

    root = tmp_path / "gallery"
    root.mkdir()
    face = cv2.imread(str(sorted((FACES_DIR / "deepface_id02").glob("*.jpg"))[0]))
    big = cv2.resize(face, (4000, 4000), interpolation=cv2.INTER_LINEAR)  # 16 MP each: a slow request
    for k in range(6):
        cv2.imwrite(str(root / f"big{k}.jpg"), big)
    huge = f"{admin_module._MAX_PHOTO_PIXELS // 1000 + 1}x1000.png"  # over the photo cap by its header alone
    (root / huge).write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR"
                              + (admin_module._MAX_PHOTO_PIXELS // 1000 + 1).to_bytes(4, "big")
                              + (1000).to_bytes(4, "big") + b"\x08\x02\x00\x00\x00" + bytes(64))
    node = _master(ros_context, tmp_path, "admin_services:=true", f"photo_root:={root}", "tick_rate_hz:=20.0")
    client = Node("admin", context=node.context)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    executor.add_node(client)
    received: list[float] = []
    client.create_subscription(NamedTrackArray, "/tracks_named", lambda _: received.append(time.monotonic()), 10)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        assert spin_until(executor, lambda: len(received) >= 2)  # /tracks_named flows
        add = client.create_client(AddPerson, "/face_reid_master/add_person")
        assert spin_until(executor, add.service_is_ready)
        paths = [f"big{k}.jpg" for k in range(6)] + [huge]
        future = add.call_async(AddPerson.Request(name="Alice", image_paths=paths))
        before = len(received)
        assert spin_until(executor, future.done, timeout_s=120.0)
        during = len(received) - before
        reply = future.result()
        assert reply.success, reply.message
        assert during >= 5, f"only {during} /tracks_named messages while the request ran: {reply.message}"
        assert reply.num_embeddings == 6 or "budget" in reply.message  # 6 x 16 MP fit the 200 MP budget
        assert f"more than {admin_module._MAX_PHOTO_PIXELS}" in reply.message  # the huge PNG, by its header
    finally:
        executor.shutdown()
        client.destroy_node()
        node.destroy_node()


class _Warnings:
    """A logger that keeps the warnings it passes on."""

    def __init__(self, logger: object) -> None:
        self.logger, self.warnings = logger, []

    def warning(self, message: str, **kwargs: object) -> object:
        self.warnings.append(message)
        return self.logger.warning(message, **kwargs)

    def __getattr__(self, name: str) -> object:
        return getattr(self.logger, name)


def test_a_retention_that_will_delete_stored_faces_is_a_warning_with_their_number(
        ros_context, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A shorter retention_unnamed_s (set while the master is unconfigured, read at configure) deletes stored
    faces without anyone asking for them by name: the master says how many, when it opens the store."""
    from rclpy.parameter import Parameter

    from face_reid_master.identity.records import LearnedFace
    from face_reid_master.storage.face_store import FaceStore

    now = time.time()
    rng = np.random.default_rng(1)
    with FaceStore(tmp_path / "faces.db", embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        store.save_faces([LearnedFace(1, rng.normal(size=(1, 128)).astype(np.float32), None, now - 7200, now - 7200),
                          LearnedFace(2, rng.normal(size=(1, 128)).astype(np.float32), None, now - 7200, now - 7200),
                          LearnedFace(3, rng.normal(size=(1, 128)).astype(np.float32), "Ann", now - 7200, now - 7200),
                          LearnedFace(4, rng.normal(size=(1, 128)).astype(np.float32), None, now - 60, now - 60)])
    node = _master(ros_context, tmp_path)  # retention_unnamed_s 0: keep forever
    recorder = _Warnings(node.get_logger())
    monkeypatch.setattr(node, "get_logger", lambda: recorder)
    try:
        assert node.trigger_configure() == OK
        assert not [w for w in recorder.warnings if "retention" in w]
        assert node.trigger_cleanup() == OK
        assert node.set_parameters([Parameter("retention_unnamed_s", value=3600.0)])[0].successful
        assert node.trigger_configure() == OK
        said = [w for w in recorder.warnings if "retention_unnamed_s" in w]
        # faces 1 and 2: unnamed, unseen for 2 h; not the named one, not the one seen a minute ago
        assert said == [f"retention_unnamed_s=3600 s: 2 of the 4 stored faces (unnamed, not seen for longer) will be "
                        f"deleted from {tmp_path / 'faces.db'} once frames arrive"], recorder.warnings
    finally:
        node.destroy_node()


_BOTH_CAMERAS = re.compile(r"camera id 'cam_a' is used by [2-9] cameras")
_BOTH_NODES = re.compile(r"camera topic '/cam_a/face_reid/frames' is published by [2-9] nodes")


def test_two_cameras_under_one_camera_id_are_a_warning_naming_both(ros_context, tmp_path: Path) -> None:
    """Two camera nodes given one camera_id in two namespaces, and two started in one namespace: /diagnostics
    WARNs naming both topics, and both publishing nodes (before: no warning anywhere)."""
    cam_b = "/cam_b/face_reid/frames"
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}",
                       "-p", f"camera_topics:=[{CAM}, {cam_b}]", "-p", "camera_topic_regex:=''",
                       "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", "check_stamps_against_clock:=false"])
    node = MasterNode(context=ctx)
    camera_a, camera_b = Node("face_reid_camera", namespace="/cam_a", context=ctx), Node(
        "face_reid_camera", namespace="/cam_b", context=ctx)
    frame_type = type(_frame(1.0))
    twin = subprocess.Popen(  # a second camera process started in /cam_a as well
        [sys.executable, "-c", f"import rclpy; from rclpy.node import Node; "
         f"from {frame_type.__module__} import {frame_type.__name__} as T; rclpy.init(); "
         f"n = Node('face_reid_camera', namespace='/cam_a'); n.create_publisher(T, '{CAM}', 10); rclpy.spin(n)"],
        env=os.environ.copy(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    executor = SingleThreadedExecutor(context=ctx)
    for n in (node, camera_a, camera_b):
        executor.add_node(n)
    got: list[DiagnosticArray] = []
    camera_a.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        pub_a = camera_a.create_publisher(type(_frame(1.0)), CAM, 10)
        pub_b = camera_b.create_publisher(type(_frame(1.0)), cam_b, 10)
        stamp = [10.0]

        def publish_and_said() -> bool:
            stamp[0] += 0.1
            pub_a.publish(_frame(stamp[0], camera="cam_a"))
            pub_b.publish(_frame(stamp[0], camera="cam_a"))  # cam_b started with camera_id cam_a by mistake
            return any(said.level == b"\x01" and _BOTH_CAMERAS.search(said.message) and _BOTH_NODES.search(said.message)
                       for said in (d.status[0] for d in got if d.status))

        # a loaded machine may discover the twin participant late: wait for a report naming both (any of them)
        assert spin_until(executor, publish_and_said, 180.0), got[-1].status[0].message if got else "no diagnostics"
        message = next(d.status[0].message for d in reversed(got) if d.status and _BOTH_CAMERAS.search(
            d.status[0].message) and _BOTH_NODES.search(d.status[0].message))
        assert f"'{CAM}' and '{cam_b}'" in message  # both topics named
        # both nodes named, by participant (a participant another test left on this domain may add a third)
        assert message.count("/cam_a/face_reid_camera (participant") >= 2
    finally:
        executor.shutdown()
        twin.terminate()
        twin.wait(30)
        for n in (camera_a, camera_b):
            n.destroy_node()
        node.destroy_node()
