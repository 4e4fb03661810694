"""Camera topic slots over real DDS (loopback): a keyless stranger's process creates more camera-like topics than
max_camera_topics and publishes garbage on them; a sealed camera started after it is still subscribed, and its
frames become tracks, with and without known_camera_ids. None of the stranger's topics holds a slot."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import spin_until
from ros_procs import procs

pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn

from face_reid_camera.common.sealing import write_network_key
from face_reid_master.ros.node import MasterNode

pytestmark = [pytest.mark.ros]

CAMERA_TOPIC = "/cam_k/face_reid/frames_sealed"
FAKES = ("/cam_k/e{k:03d}/face_reid/frames_sealed", "/x{k:02d}/cam_k/face_reid/frames_sealed")  # 64 + 8
FAKE_COUNTS = (64, 8)


def _fake(name: str) -> bool:
    return name != CAMERA_TOPIC and name.endswith("/face_reid/frames_sealed")


@pytest.mark.parametrize("known", ["['']", "[cam_k]"], ids=["any_camera", "known_camera_ids"])
def test_a_strangers_keyless_topics_do_not_keep_a_camera_out(ros_context, ros_domain_id: int, tmp_path: Path,
                                                              known: str) -> None:
    key = write_network_key(tmp_path / "network.key")
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={key}", "-p", f"known_camera_ids:={known}",
                       "-p", "topic_discovery_period_s:=0.2", "-p", "body_appearance_tracking:=false"])
    master = MasterNode(context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(master)
    fake_args = [str(procs.PROCS / "fake_camera_topics.py"), "--seconds", "240"]
    for pattern, count in zip(FAKES, FAKE_COUNTS, strict=True):
        fake_args += ["--pattern", pattern, "--count", str(count)]
    running = []
    try:
        assert master.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert master.trigger_activate() == TransitionCallbackReturn.SUCCESS
        running.append(procs.start(fake_args, ros_domain_id, tmp_path / "fakes.log"))
        assert procs.json_line(running[0], 60.0) == {"topics": sum(FAKE_COUNTS)}
        # the master knows every fake topic and its discovery has taken them in (subscribed or refused)
        assert spin_until(executor, lambda: sum(_fake(n) for n, _ in master.get_topic_names_and_types())
                          == sum(FAKE_COUNTS), 60.0)
        assert spin_until(executor, lambda: len(master.cameras.subscribed) >= 8, 60.0)
        # then the real camera starts
        running.append(procs.start([str(procs.PROCS / "sealed_walker.py"), "--key", str(key), "--camera", "cam_k",
                                    "--seconds", "60", "--wait-s", "120"], ros_domain_id, tmp_path / "camera.log"))
        assert spin_until(executor, lambda: any("cam_k" in t.cameras for t in master.core.tracks()), 90.0), \
            f"no track from cam_k; subscribed: {sorted(master.cameras.subscribed)[:5]}..."
        assert master.core.stats.frames_applied > 0
        assert set(master.cameras.slots.slots) == {CAMERA_TOPIC}  # the only slot taken
        if known != "['']":  # /cam_k/eNNN/... merely contains the camera id: refused unread
            assert spin_until(executor, lambda: len(master.cameras.unknown) == FAKE_COUNTS[0], 30.0)
            assert not any(t.startswith("/cam_k/e") for t in master.cameras.subscribed)
        # the stranger's topics that were heard are released, counted and said
        assert spin_until(executor, lambda: master.cameras.slots.released >= 8, 30.0)
        report = master.diagnostics(master.now_s())
        assert report.values["camera_topics"] == "1" and int(report.values["camera_topics_released"]) >= 8
        assert int(report.values["rejected_topic_released"]) >= 8
        assert "camera topic(s) released so far" in report.message
        assert len(master.cameras.slots.probation) <= 16
    finally:
        for proc in reversed(running):
            procs.stop(proc)
        executor.shutdown()
        master.destroy_node()
