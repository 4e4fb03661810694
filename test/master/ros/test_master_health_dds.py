"""The master's /diagnostics tells the truth over DDS: a face store whose writes fail (disk full) is an ERROR with
the reason, a WARN once writes succeed again; two masters on one domain both warn about the other."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from conftest import spin_until

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node

from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.ros.convert import frame_record_to_msg
from face_reid_master.ros.node import MasterNode
from face_reid_master.storage.face_store import FaceStore, FaceStoreError

OK = TransitionCallbackReturn.SUCCESS
CAM = "/cam_a/face_reid/frames"


def _master(ros_context, db: Path, *extra: str) -> MasterNode:
    params = ["embedding_space:=dlib_resnet_v1", "identity_period_s:=0.0", "check_stamps_against_clock:=false",
              f"db_path:={db}", f"camera_topics:=[{CAM}]", "camera_topic_regex:=''", *extra]
    return MasterNode(context=ros_context(["--ros-args", *[a for p in params for a in ("-p", p)]]))


def _frame(stamp_s: float, seed: int, x: float = 1.0):
    v = np.random.default_rng(seed).normal(size=128).astype(np.float32)
    person = PersonRecord(np.array([x, 2.0, 0.0]), 0.05, 1.7, v * 1.4 / np.linalg.norm(v), 0.9, 0.8)
    return frame_record_to_msg(CameraFrameRecord("cam_a", stamp_s, (person,), "world"), stamp_s)


def _status(got: list[DiagnosticArray]) -> DiagnosticStatus | None:
    mine = [s for arr in got for s in arr.status if s.name == "face_reid_master"]
    return mine[-1] if mine else None


@pytest.mark.slow
def test_store_write_failures_are_an_error_on_diagnostics_then_a_warning(ros_context, tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    node = _master(ros_context, tmp_path / "faces.db")
    probe = Node("probe", context=node.context)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    executor.add_node(probe)
    got: list[DiagnosticArray] = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
    real_save = FaceStore.save_faces

    def disk_full(self, faces):
        raise FaceStoreError(f"face store {self.path}: database or disk is full")

    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        monkeypatch.setattr(FaceStore, "save_faces", disk_full)
        for k in range(5):  # a new face: saved at once, which fails
            node._on_frame(_frame(10.0 + 0.1 * k, seed=1))
        node.store.flush()
        got.clear()
        assert spin_until(executor, lambda: (s := _status(got)) is not None and s.level == DiagnosticStatus.ERROR,
                          timeout_s=60.0), _status(got)
        status = _status(got)
        assert "disk full" in status.message and "not saved" in status.message, status.message
        monkeypatch.setattr(FaceStore, "save_faces", real_save)
        for k in range(5):  # the same person: the face's new features are saved (save_interval_s 1 s)
            node._on_frame(_frame(12.0 + 0.1 * k, seed=1))
        node.store.flush()
        got.clear()
        assert spin_until(executor, lambda: (s := _status(got)) is not None and s.level == DiagnosticStatus.WARN
                          and "write(s) failed, the writes since succeed" in s.message, timeout_s=60.0), _status(got)
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_two_masters_on_one_domain_both_warn(ros_context, tmp_path: Path) -> None:
    a = _master(ros_context, tmp_path / "a.db")
    b = _master(ros_context, tmp_path / "b.db")  # same name and namespace, own participant: a second robot
    executors = [SingleThreadedExecutor(context=n.context) for n in (a, b)]
    for ex, n in zip(executors, (a, b), strict=True):
        ex.add_node(n)
    try:
        for n in (a, b):
            assert n.trigger_configure() == OK and n.trigger_activate() == OK

        def both_warn() -> bool:
            for ex in executors:
                ex.spin_once(timeout_sec=0.05)
            # the other's node name arrives with discovery too (until then: _NODE_NAME_UNKNOWN_)
            return all("another publisher of /tracks_named" in (m := n.diagnostics(n.now_s()).message)
                       and "/face_reid_master" in m for n in (a, b))

        deadline = time.monotonic() + 60.0
        while not both_warn():  # DDS discovery: each master's graph learns the other's publisher
            assert time.monotonic() < deadline, [n.diagnostics(n.now_s()).message for n in (a, b)]
        report = a.diagnostics(a.now_s())
        assert report.values["other_output_publishers"] == "1" and "/face_reid_master" in report.message
        assert b.trigger_deactivate() == OK  # b's publisher goes: a stops warning
        deadline = time.monotonic() + 60.0
        while "another publisher" in a.diagnostics(a.now_s()).message:
            executors[0].spin_once(timeout_sec=0.05)
            assert time.monotonic() < deadline
    finally:
        for ex in executors:
            ex.shutdown()
        for n in (a, b):
            n.destroy_node()


def test_faces_lost_at_open_warn_on_diagnostics(ros_context, tmp_path: Path) -> None:
    """Faces saved before but missing from the database at open (its last writes lost: rows removed behind the
    store's back, its id ledger remembers them) make the master's status WARN, naming them."""
    import sqlite3

    from face_reid_master.identity.records import LearnedFace

    db = tmp_path / "faces.db"
    with FaceStore(db, embedding_space="dlib_resnet_v1") as store:
        store.save_faces([LearnedFace(k, np.full((1, 128), 0.1 * k, np.float32) + np.eye(1, 128, k, dtype=np.float32))
                          for k in (1, 2, 3)])
    with sqlite3.connect(db) as conn:  # what a lost -wal does: the rows are gone, the ledger says they were saved
        conn.execute("DELETE FROM features WHERE face_id IN (2, 3)")
        conn.execute("DELETE FROM faces WHERE face_id IN (2, 3)")
    node = _master(ros_context, db)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        report = node.diagnostics(node.now_s())
        assert report.level == 1 and "2 learned face(s) lost at open" in report.message and "ids 2, 3" in report.message
    finally:
        node.destroy_node()


def test_face_ids_that_cannot_be_reserved_are_an_error_on_diagnostics(ros_context, tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A new person while the store cannot reserve face ids (disk full): no face id is published, the master's
    status is ERROR saying so (with the reason), counted in faces_refused_no_id; it clears once the store writes."""

    def disk_full(self, upto):
        raise FaceStoreError(f"face store {self.path}: database or disk is full")

    node = _master(ros_context, tmp_path / "faces.db", "save_interval_s:=0.5")
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        monkeypatch.setattr(FaceStore, "reserve_face_ids", disk_full)
        for k in range(8):  # a new person: decided after a few observations, but no id can be reserved
            node._on_frame(_frame(10.0 + 0.1 * k, seed=1))
        tracks = node.core.tracks()
        assert tracks and all(t.face_id == 0 for t in tracks)
        report = node.diagnostics(node.now_s())
        assert report.level == 2 and "new people get no face id" in report.message, report.message
        assert "disk full" in report.message and int(report.values["faces_refused_no_id"]) >= 1, report
        monkeypatch.undo()
        node.core.tick(12.0)  # the retry (every save_interval_s) succeeds
        report = node.diagnostics(node.now_s())
        assert report.level < 2 and "face id" not in report.message, report.message  # (a WARN: the test's stamps)
    finally:
        node.destroy_node()
