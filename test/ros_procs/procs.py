"""Start and stop the test's ROS 2 processes (real DDS, loopback only, per-test domain)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PROCS = Path(__file__).resolve().parent


def ros_env(domain_id: int) -> dict[str, str]:
    """Environment of a test process: its own domain, discovery limited to loopback."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PYTHONUNBUFFERED"] = "1"
    env["OMP_NUM_THREADS"] = "1"
    return env


def start(args: list[str], domain_id: int, log_path: Path | None = None) -> subprocess.Popen[str]:
    """Start ``python ARGS`` (a helper script or ``-m module``) in its own process group."""
    stderr = open(log_path, "w") if log_path else subprocess.DEVNULL
    return subprocess.Popen(
        [sys.executable, *args], env=ros_env(domain_id), cwd=REPO, stdout=subprocess.PIPE, stderr=stderr,
        text=True, start_new_session=True,
    )


def stop(proc: subprocess.Popen[str], timeout_s: float = 5.0) -> None:
    """SIGINT, then SIGKILL the process group if it does not exit."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=timeout_s)
        except (subprocess.TimeoutExpired, ProcessLookupError):
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait(timeout=timeout_s)


def run_pids(domain_id: int) -> list[int]:
    """Live processes started by ``face_reid_master.demo.children.start_child`` (marked FACE_REID_DEMO_RUN) on
    ``domain_id`` (Linux /proc), zombies excluded."""
    pids = []
    for env_file in Path("/proc").glob("[0-9]*/environ"):
        try:
            env = env_file.read_bytes().split(b"\0")
        except OSError:
            continue
        if b"ROS_DOMAIN_ID=%d" % domain_id in env and any(e.startswith(b"FACE_REID_DEMO_RUN=") for e in env):
            status = (env_file.parent / "status").read_text() if (env_file.parent / "status").exists() else ""
            if "\nState:\tZ" not in status:
                pids.append(int(env_file.parent.name))
    return pids
