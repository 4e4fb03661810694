"""face-reid-goto's known names on a secured network (in-process nodes, loopback DDS): its ~/list_faces requests
are sealed for the master and only the master's sealed reply is taken, so a keyless server on the same name
cannot plant names, and the secured master (which answers keyless listings with nothing) still gives its names."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import spin_until

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node

from face_reid_camera.common.sealing import write_network_key
from face_reid_master.ros.goto_node import GotoNode
from face_reid_master.ros.node import MasterNode
from face_reid_msgs.srv import ListFaces

pytestmark = pytest.mark.ros
OK = TransitionCallbackReturn.SUCCESS


def _store_alice(db: Path) -> None:
    from face_reid_master.identity.records import LearnedFace
    from face_reid_master.storage.face_store import FaceStore

    now = time.time()
    feats = np.random.default_rng(0).normal(size=(2, 128)).astype(np.float32)
    with FaceStore(db, embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        store.save_faces([LearnedFace(1, feats, "Alice", now, now, 3)])


def test_goto_takes_names_only_from_the_masters_sealed_reply(ros_context, tmp_path: Path) -> None:
    key_path = write_network_key(tmp_path / "network.key")
    db = tmp_path / "faces.db"
    _store_alice(db)
    ctx = ros_context(["--ros-args", "-p", f"network_key_path:={key_path}",
                       "-p", f"face_reid_master:db_path:={db}",
                       "-p", "face_reid_master:embedding_space:=dlib_resnet_v1",
                       "-p", "face_reid_master:body_appearance_tracking:=false",
                       "-p", "face_reid_goto:names_refresh_period_s:=0.5"])
    goto = GotoNode(context=ctx)
    rogue = Node("rogue", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (goto, rogue):
        executor.add_node(node)
    master: MasterNode | None = None

    def planted(request: Any, response: Any) -> Any:
        response.face_ids, response.names, response.num_features, response.last_seen_s = [7], ["Mallory"], [1], [1.0]
        return response

    known = lambda: set(goto.core._known.values()) if goto.core is not None else set()  # noqa: E731
    try:
        # only a keyless server on the master's service name: its names are refused, counted
        server = rogue.create_service(ListFaces, "/face_reid_master/list_faces", planted)
        assert goto.trigger_configure() == OK and goto.trigger_activate() == OK
        assert spin_until(executor, lambda: goto.rejected.get("names_unsealed", 0) >= 2, 30.0), (goto.rejected,
                                                                                                  known())
        assert "Mallory" not in known()
        rogue.destroy_service(server)
        # the secured master: its names, from its sealed reply
        master = MasterNode(context=ctx)
        executor.add_node(master)
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        assert spin_until(executor, lambda: "Alice" in known(), 30.0), (goto.rejected, known())
        assert known() == {"Alice"}
        assert master.admin.calls.get("list_faces", 0) >= 1 and not master.admin.refusals.get("list_faces", 0)
    finally:
        executor.shutdown()
        for node in (goto, rogue, *([master] if master is not None else [])):
            node.destroy_node()
