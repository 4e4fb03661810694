"""``face-reid-eval --live``: a short simulated scenario through the real master node over DDS, compared with
the offline evaluation of the same scenario (the master core run directly). ~50 s."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import FACES_DIR
from ros_procs import procs

from face_reid_master.evaluation import cli as eval_cli
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.sim import cli as sim_cli


def test_frame_record_round_trips_through_the_message() -> None:
    pytest.importorskip("face_reid_msgs.msg")
    from face_reid_master.ros.convert import frame_from_msg, frame_record_to_msg

    emb = np.linspace(-0.2, 0.2, 128).astype(np.float32)
    frame = CameraFrameRecord("cam1", 12.5, (PersonRecord(np.array([1.0, -2.0, 0.9]), 0.07, 1.71, emb, 0.93, 0.61),
                                             PersonRecord(np.array([0.5, 0.25, 1.0]), 0.1, 1.6)))
    back = frame_from_msg(frame_record_to_msg(frame, 1_700_000_000.1234))
    assert back.camera_id == "cam1" and back.frame_id == "world"
    assert back.stamp_s == pytest.approx(1_700_000_000.1234, abs=1e-6)
    assert len(back.people) == 2 and back.people[1].embedding is None
    first = back.people[0]
    np.testing.assert_allclose(first.position_world, [1.0, -2.0, 0.9])
    np.testing.assert_allclose(first.embedding, emb)
    assert (first.position_std_m, first.height_m) == pytest.approx((0.07, 1.71), abs=1e-6)
    assert (first.face_score, first.face_quality) == pytest.approx((0.93, 0.61), abs=1e-6)


@pytest.mark.slow
@pytest.mark.ros
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_live_evaluation_matches_offline(ros_domain_id: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                         ) -> None:
    pytest.importorskip("rclpy")
    pytest.importorskip("face_reid_msgs.msg")
    scenario = tmp_path / "s"
    assert sim_cli.main(["--faces", str(FACES_DIR), "--people", "3", "--cameras", "2", "--duration", "40",
                         "--seed", "2", "--out", str(scenario), "--quiet"]) == 0
    # the fixture faces may include people the shipped face fit saw: this test compares live with offline
    assert eval_cli.main([str(scenario), "--no-mot", "--quiet", "--allow-fitted",
                          "--out", str(tmp_path / "offline.json")]) == 0
    capsys.readouterr()
    offline = json.loads((tmp_path / "offline.json").read_text())

    t0 = time.monotonic()
    run = subprocess.run(
        [sys.executable, "-m", "face_reid_master.evaluation.cli", str(scenario), "--live", "--domain-id",
         str(ros_domain_id), "--allow-fitted", "--out", str(tmp_path / "live.json")],
        env=procs.ros_env(ros_domain_id), cwd=procs.REPO, capture_output=True, text=True, timeout=120,
    )
    wall_s = time.monotonic() - t0
    assert run.returncode == 0, f"stdout:\n{run.stdout}\nstderr:\n{run.stderr}"
    live = json.loads(run.stdout)
    assert live == json.loads((tmp_path / "live.json").read_text())
    assert live["mode"] == "live" and "mode" not in offline
    assert live["protocol"] == offline["protocol"] and live["protocol"]["honest"] is False  # marked as not a test
    assert f"ROS_DOMAIN_ID={ros_domain_id}" in run.stderr
    work = re.search(r"work folder (\S+)", run.stderr)
    assert work and not Path(work.group(1)).exists(), "the temporary folder (face database) must be deleted"
    assert not procs.run_pids(ros_domain_id), "the master node outlived the evaluation"
    assert wall_s < 40 + 30

    # every recorded frame was sent over DDS in real time, and each was answered by a /tracks_named message
    # stamped with it or a later frame (the master applies a cycle's frames together)
    t = live["transport"]
    assert t["frames_sent"] == live["frames"] == offline["frames"] == live["scenario"]["frames"]
    assert t["detections_sent"] == offline["detections"]
    assert t["frames_answered"] == t["frames_sent"] and live["frames_rejected"] == 0
    assert t["tracks_named_messages"] >= 0.5 * t["frames_sent"]  # cycles of a frame or two, uncapped
    assert t["frames_sent_late_50ms"] <= 0.02 * t["frames_sent"]
    assert t["frame_to_tracks_latency_ms"]["median"] < 100

    # the published tracks tell the same story as the core run offline
    assert live["attribution"]["samples_near_nobody"] <= 0.02 * live["attribution"]["published_track_samples"]
    lr, orr = live["reidentification"], offline["reidentification"]
    assert orr["success"] >= 2  # the scenario has re-identifications to measure
    assert lr["success"] >= 2 and abs(lr["success"] - orr["success"]) <= 1, (lr, orr)
    assert lr["failure"] <= orr["failure"] + 1, (lr, orr)
    assert live["faces"]["people_with_a_face"] == 3 and live["faces"]["faces_of_no_person"] == 0
    assert live["first_appearance"]["failure_wrong_person"] <= offline["first_appearance"]["failure_wrong_person"] + 1
    assert abs(live["tracker"]["tracks_evaluated"] - offline["tracker"]["tracks_evaluated"]) <= 2
    assert live["tracker"]["false_positive_tracks"] <= 1
    assert live["predefined_people"]["wrong_name"] == 0 and live["predefined_people"]["other_tracks_named"] == 0


def test_a_frame_is_answered_by_the_first_message_stamped_at_or_after_it() -> None:
    """Cycles stamp their message with the newest frame applied: frames 1.0 and 1.1 are answered by the message
    stamped 1.1 (arrived at 1.15); 1.2 by the one stamped 1.3, although an earlier-arriving message exists only
    for older stamps; 2.0 by nothing."""
    from face_reid_master.evaluation.live import frame_latencies

    lat, has = frame_latencies(np.array([1.0, 1.1, 1.2, 2.0]), np.array([1.3, 1.1, 0.5]),
                               np.array([1.36, 1.15, 0.52]))
    assert has.tolist() == [True, True, True, False]
    np.testing.assert_allclose(lat, [0.15, 0.05, 0.16])
    lat, has = frame_latencies(np.array([1.0]), np.zeros(0), np.zeros(0))
    assert lat.size == 0 and not has.any()
