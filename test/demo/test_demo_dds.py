"""face-reid-demo over real DDS: a short pixel-level scenario through separate player, camera-node and master
processes (loopback only, this test's domain), the summary checked against bounds; Ctrl-C stops everything.

The demo runs as it would from a shell (``python -m face_reid_master.demo``), so this also checks its
exit status, its output, that it deletes its temporary folder and that none of its processes outlives it.
"""

from __future__ import annotations

import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _demo_pids(domain_id: int) -> list[int]:
    """Processes started by a demo (marked FACE_REID_DEMO_RUN) on ``domain_id``."""
    return procs.run_pids(domain_id)


def _demo_cmd(domain_id: int, *extra: str) -> list[str]:
    return [sys.executable, "-m", "face_reid_master.demo", "--domain-id", str(domain_id), *extra]


def _env() -> dict[str, str]:
    env = procs.ros_env(0)
    env.pop("ROS_DOMAIN_ID")  # the demo chooses its own (--domain-id here)
    env["CI"] = "true"  # compact table every 5 s
    return env


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_demo_short_scenario_metrics(ros_domain_id: int, tmp_path: Path) -> None:
    summary_path = tmp_path / "summary.json"
    t0 = time.monotonic()
    run = subprocess.run(
        _demo_cmd(ros_domain_id, "--duration-s", "35", "--people", "2", "--gallery-people", "1",
                  "--json", str(summary_path)),
        env=_env(), cwd=procs.REPO, capture_output=True, text=True, timeout=180,
    )
    wall_s = time.monotonic() - t0
    assert run.returncode == 0, f"stdout:\n{run.stdout}\nstderr:\n{run.stderr}"
    out = run.stdout
    assert f"ROS_DOMAIN_ID={ros_domain_id}, discovery on localhost only" in out
    assert re.search(r"t = +\d+\.\d s / 35 s: \d tracks; #\d+ ", out), out  # live table lines (compact)
    assert "Summary: 35 s, 2 cameras, 2 people" in out
    work = re.search(r"work folder (\S+)", out)
    assert work and not Path(work.group(1)).exists(), "the temporary folder (face database) must be deleted"
    assert not _demo_pids(ros_domain_id), "a demo process outlived the demo"
    assert wall_s < 35 + 40

    summary = json.loads(summary_path.read_text())
    people = {p["name"]: p for p in summary["people"]}
    assert len(people) == 2
    named = next(p for p in people.values() if p["in_gallery"])
    unnamed = next(p for p in people.values() if not p["in_gallery"])
    for p in people.values():
        assert p["returns"] == 1
        assert 1 <= p["tracks"] <= 3, p  # one per visit (a tracker loss in view may add one)
        assert p["reid_wrong"] == 0, p  # never given the other person's face (nor a new id)
        assert p["names_wrong"] == 0, p
    reid = summary["reidentification"]
    assert reid["success"] >= 1 and reid["failure"] == 0, reid
    assert reid["mean_reid_time_s"] is not None and reid["mean_reid_time_s"] < 5.0
    assert named["names_right"] >= 1, named  # the gallery person's name appears
    assert unnamed["names_right"] == 0 and unnamed["names_wrong"] == 0
    assert summary["false_tracks"] <= 1
    assert summary["median_position_error_m"] < 0.25
    frames = [p["frames"] for p in summary["players"].values()]
    assert len(frames) == 2 and min(frames) >= 0.8 * 35 * 5, summary["players"]  # real time at 5 Hz


def _lines(proc: subprocess.Popen[str]) -> queue.Queue[str]:
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    return lines


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_ctrl_c_stops_every_process(ros_domain_id: int) -> None:
    proc = subprocess.Popen(
        _demo_cmd(ros_domain_id, "--duration-s", "40", "--people", "2", "--gallery-people", "1"),
        env=_env(), cwd=procs.REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True,
    )
    lines = _lines(proc)
    seen = []
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            try:
                seen.append(lines.get(timeout=1.0))
            except queue.Empty:
                continue
            if "playing the scenario" in seen[-1]:
                break
        assert any("playing the scenario" in s for s in seen), "".join(seen)
        time.sleep(2.0)
        children = _demo_pids(ros_domain_id)
        assert len(children) >= 5, children  # master + 2 camera nodes + 2 players (+ the demo itself)
        os.kill(proc.pid, signal.SIGINT)
        proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    time.sleep(0.5)
    while not lines.empty():
        seen.append(lines.get())
    text = "".join(seen)
    assert proc.returncode == 130, text
    assert "interrupted, stopping every process" in text
    assert not _demo_pids(ros_domain_id), "a demo process outlived Ctrl-C"
    work = re.search(r"work folder (\S+)", text)
    assert work and not Path(work.group(1)).exists()
