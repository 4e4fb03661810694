"""Memory a stranger's traffic takes from a secured master comes back (real DDS, the master as its own process):
forged 4 MB sealed messages on camera topics, all refused, leave the master's resident memory where it was."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO_ROOT, spin_until

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TOPICS, PER_TOPIC, SIZE = 4, 20, 4 * 1024 * 1024


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return 0.0


def test_refused_traffic_gives_its_memory_back(ros_context, tmp_path: Path) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_camera.common.sealing import write_network_key
    from face_reid_msgs.msg import Sealed

    write_network_key(tmp_path / "network.key")
    master = subprocess.Popen(
        [sys.executable, "-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}",
         "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "topic_discovery_period_s:=0.2",
         "-p", "body_appearance_tracking:=false"], cwd=REPO_ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    ctx = ros_context()
    node = Node("stranger", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    refused: list[int] = [0, 0]  # messages refused, camera topics released

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == "face_reid_master":
                values = {kv.key: kv.value for kv in status.values}
                refused[0] = sum(int(v) for k, v in values.items() if k.startswith("rejected_sealed_")
                                 or k == "rejected_oversized")
                refused[1] = int(values.get("camera_topics_released", 0))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    try:
        qos = QoSProfile(depth=PER_TOPIC, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        pubs = [node.create_publisher(Sealed, f"/atk{k}/face_reid/frames_sealed", qos) for k in range(TOPICS)]
        assert spin_until(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs), 90.0), \
            master.stderr.read1().decode(errors="replace") if master.poll() is not None else "no subscription"
        before = _rss_mb(master.pid)
        forged = Sealed(sender_id="atk", counter=time.time_ns(), nonce=bytes(12), ciphertext=bytes(SIZE))
        for _ in range(PER_TOPIC):
            for pub in pubs:
                pub.publish(forged)
        # every one arrived and was refused, or its topic was released first (nothing on it opened with the key)
        assert spin_until(executor, lambda: refused[0] >= TOPICS * PER_TOPIC or refused[1] >= TOPICS, 90.0)
        assert spin_until(executor, lambda: _rss_mb(master.pid) < before + 48.0, 30.0), \
            f"{TOPICS * PER_TOPIC * SIZE >> 20} MB refused: RSS {before:.0f} -> {_rss_mb(master.pid):.0f} MB"
        assert master.poll() is None
    finally:
        executor.shutdown()
        node.destroy_node()
        master.terminate()
        try:
            master.wait(30)
        except subprocess.TimeoutExpired:
            master.kill()
