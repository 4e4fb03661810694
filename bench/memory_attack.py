"""Benchmark: the master's memory under traffic it must refuse, and after it (an attacker on the same domain).

Separate processes on a private ROS domain (discovery on loopback only), the real ``face-reid-master`` node:

- ``sealed_flood``: a secured master (network key); a keyless peer publishes forged 4 MB
  face_reid_msgs/Sealed messages on 16 topics matching the master's ``sealed_topic_regex`` (40 per topic);
- ``plain_fuzz``: an unsecured master; the same peer publishes 4 MB CameraFrame messages (one person with
  a 1,000,000-value embedding: refused) on 16 camera topics, then typed garbage on them.

Each case reports the master's resident memory (RSS, MB) before the traffic, its peak during it, 30 s after it
(``--settle-s``), the growth (``after - before``) and the ratio ``after / before``. Prints ONE JSON object.

Usage: python bench/memory_attack.py [--domain-id N] [--settle-s 30] [--messages 40] [--topics 16]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
MB = 1024 * 1024


def _rss_mb(pid: int) -> float:
    """The resident set size of process ``pid`` in MB (0 when it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


class _PeakSampler(threading.Thread):
    """Samples a process's RSS every 0.1 s; ``peak`` is the largest seen."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid, self.peak, self._done = pid, 0.0, threading.Event()

    def run(self) -> None:
        while not self._done.is_set():
            self.peak = max(self.peak, _rss_mb(self.pid))
            time.sleep(0.1)

    def stop(self) -> float:
        self._done.set()
        self.join()
        return self.peak


def _start_master(work: Path, secured: bool) -> subprocess.Popen[bytes]:
    args = ["-p", f"db_path:={work / 'faces.db'}", "-p", "topic_discovery_period_s:=0.2",
            "-p", "body_appearance_tracking:=false"]
    if secured:
        from face_reid_camera.common.sealing import write_network_key

        write_network_key(work / "network.key")
        args += ["-p", f"network_key_path:={work / 'network.key'}"]
    return subprocess.Popen([sys.executable, "-m", "face_reid_master.ros.node", "--ros-args", *args],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=open(work / "master.log", "wb"))


def _wait(condition: Any, node: Any, timeout_s: float, what: str) -> None:
    import rclpy

    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        rclpy.spin_once(node, timeout_sec=0.05)


def _attack(node: Any, secured: bool, topics: int, messages: int) -> int:
    """Publish the hostile traffic once every topic is matched by the master; returns the messages sent."""
    import numpy as np
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_msgs.msg import CameraFrame, PersonObservation, Sealed

    qos = QoSProfile(depth=messages, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    rng = np.random.default_rng(1)
    if secured:
        pubs = [node.create_publisher(Sealed, f"/atk{i}/face_reid/frames_sealed", qos) for i in range(topics)]
        msg: Any = Sealed(sender_id="atk", counter=time.time_ns(), nonce=bytes(12),
                          ciphertext=rng.integers(0, 256, 4 * MB, dtype=np.uint8).tobytes())
    else:
        pubs = [node.create_publisher(CameraFrame, f"/atk{i}/face_reid/frames", qos) for i in range(topics)]
        msg = CameraFrame(camera_id="atk")
        person = PersonObservation(face_found=True)
        person.embedding = rng.normal(size=MB).astype(np.float32).tolist()  # 4 MB, refused as malformed
        msg.people = [person]
    _wait(lambda: all(p.get_subscription_count() > 0 for p in pubs), node, 60.0, "the master to subscribe")
    sent = 0
    for _ in range(messages):
        for pub in pubs:
            pub.publish(msg)
            sent += 1
        node.get_clock()  # keep the loop cheap: publishing is what costs
    if not secured:  # then typed garbage: short messages of every kind the fuzz test sends
        for k in range(messages * 10):
            pubs[k % topics].publish(CameraFrame(camera_id=str(k), people=[PersonObservation()] * (k % 7)))
            sent += 1
    return sent


def run_case(secured: bool, topics: int, messages: int, settle_s: float) -> dict[str, Any]:
    import rclpy

    with tempfile.TemporaryDirectory(prefix="face_reid_memory_") as tmp:
        work = Path(tmp)
        master = _start_master(work, secured)
        rclpy.init()
        node = rclpy.create_node("memory_attacker")
        try:
            _wait(lambda: any(n == "face_reid_master" for n, _ in node.get_node_names_and_namespaces())
                  and node.count_publishers("/tracks_named_sealed" if secured else "/tracks_named") > 0,
                  node, 120.0, "the master")
            time.sleep(2.0)  # start-up allocations settled
            before = _rss_mb(master.pid)
            sampler = _PeakSampler(master.pid)
            sampler.start()
            t0 = time.monotonic()
            sent = _attack(node, secured, topics, messages)
            deadline = time.monotonic() + settle_s
            while time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.1)
            peak = sampler.stop()
            after = _rss_mb(master.pid)
            alive = master.poll() is None
            return {"messages_sent": sent, "attack_s": round(time.monotonic() - t0 - settle_s, 1),
                    "rss_before_mb": round(before, 1), "rss_peak_mb": round(peak, 1),
                    "rss_after_settle_mb": round(after, 1), "growth_mb": round(after - before, 1),
                    "after_over_before": round(after / max(before, 1e-9), 2), "master_alive": alive}
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
            master.terminate()
            try:
                master.wait(30)
            except subprocess.TimeoutExpired:
                master.kill()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain-id", type=int, default=77)
    parser.add_argument("--settle-s", type=float, default=30.0)
    parser.add_argument("--messages", type=int, default=40, help="messages per topic")
    parser.add_argument("--topics", type=int, default=16)
    parser.add_argument("--case", choices=("both", "sealed", "plain"), default="both")
    args = parser.parse_args(argv)
    os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    sys.path.insert(0, str(ROOT))
    out: dict[str, Any] = {"topics": args.topics, "messages_per_topic": args.messages, "settle_s": args.settle_s}
    if args.case in ("both", "sealed"):
        out["sealed_flood"] = run_case(True, args.topics, args.messages, args.settle_s)
    if args.case in ("both", "plain"):
        out["plain_fuzz"] = run_case(False, args.topics, args.messages, args.settle_s)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
