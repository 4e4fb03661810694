"""The master node survives bad input: a corrupt database, unknown cameras, malformed embeddings."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

pytestmark = pytest.mark.ros


def _wait_for(path: Path, text: str, timeout_s: float) -> str:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        content = path.read_text() if path.exists() else ""
        if text in content:
            return content
        time.sleep(0.2)
    return path.read_text() if path.exists() else ""


def test_corrupt_db_unknown_camera_and_bad_embeddings(ros_domain_id: int, tmp_path: Path) -> None:
    db = tmp_path / "faces.db"
    db.write_bytes(b"this is not a database" * 100)
    rng = np.random.default_rng(0)
    emb = tmp_path / "emb.npz"
    np.savez(emb, short=rng.normal(0, 0.05, (3, 100)).astype(np.float32),
             nan=np.full((3, 128), np.nan, np.float32), good=rng.normal(0, 0.05, (3, 128)).astype(np.float32))
    log = tmp_path / "master.log"
    master = procs.start(
        ["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={db}", "-p", "known_camera_ids:=[cam_a]",
         "-p", "topic_discovery_period_s:=0.5", "-p", "stats_log_period_s:=1.0"],
        ros_domain_id, log,
    )
    segments = {
        "cam_a": [{"t0": 0.0, "t1": 3.0, "people": [
            {"x": 0.0, "y": 0.0, "identity": "short", "photos": [0, 1, 2]},
            {"x": 0.0, "y": 2.0, "identity": "nan", "photos": [0, 1, 2]},
            {"x": 2.0, "y": 0.0, "identity": "good", "photos": [0, 1, 2]},
        ]}],
        "intruder": [{"t0": 0.0, "t1": 3.0, "people": [{"x": 5.0, "y": 5.0}]}],
    }
    cams = []
    for cid, segs in segments.items():
        plan = tmp_path / f"{cid}.json"
        plan.write_text(json.dumps({"rate_hz": 10, "embeddings": str(emb), "segments": segs}))
        cams.append(procs.start([str(procs.PROCS / "publish_camera_frames.py"), "--camera-id", cid, "--topic",
                                 f"/{cid}/face_reid/frames", "--plan", str(plan)], ros_domain_id,
                                tmp_path / f"{cid}.log"))
    try:
        for cam in cams:
            cam.wait(timeout=60)
        text = _wait_for(log, "embeddings_rejected_nonfinite", 10.0)
        alive = master.poll() is None
    finally:
        for p in (*cams, master):
            procs.stop(p)
    assert alive, text
    assert "Traceback" not in text
    # the corrupt database was set aside loudly and a fresh one started
    assert "was corrupt" in text
    backups = list(tmp_path.glob("faces.db.corrupt-*"))
    assert len(backups) == 1 and backups[0].read_bytes().startswith(b"this is not a database")
    # unknown camera and malformed embeddings were counted, not crashed on
    assert "unknown camera id 'intruder'" in text
    assert "embeddings_rejected_length" in text and "embeddings_rejected_nonfinite" in text
