"""The DDS tests' processes: started and stopped with :mod:`face_reid_master.demo.children` (own process group,
dying with pytest, loopback-only discovery on the test's domain), plus what only the tests need."""

from __future__ import annotations

import json
import select
import subprocess
import time
from pathlib import Path
from typing import Any

from conftest import REPO_ROOT as REPO

from face_reid_master.demo.children import child_env, spawn, stop_processes

PROCS = Path(__file__).resolve().parent


def ros_env(domain_id: int) -> dict[str, str]:
    """Environment of a test process: its own domain, discovery limited to loopback, this checkout importable."""
    return child_env(domain_id)


def start(args: list[str], domain_id: int, log_path: Path | None = None) -> subprocess.Popen[str]:
    """Start ``python ARGS`` (a helper script or ``-m module``) from the repository; stdout is a pipe, stderr goes
    to ``log_path`` (default: discarded)."""
    if log_path is None:
        return spawn(args, ros_env(domain_id), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=REPO)
    with open(log_path, "w") as log:  # the child has its own copy
        return spawn(args, ros_env(domain_id), stdout=subprocess.PIPE, stderr=log, cwd=REPO)


def stop(proc: subprocess.Popen[str], timeout_s: float = 5.0) -> None:
    """SIGINT, then SIGKILL the process group if it does not exit."""
    stop_processes([proc], timeout_s)


def run_pids(domain_id: int) -> list[int]:
    """Live processes started for a run by ``face_reid_master.demo.children`` (marked FACE_REID_DEMO_RUN) on
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


def json_line(proc: subprocess.Popen[str], timeout_s: float) -> dict[str, Any]:
    """The next JSON line a helper process prints on stdout (other lines skipped); AssertionError when it exits
    first or nothing comes within ``timeout_s``."""
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.5)
        if ready:
            line = proc.stdout.readline()
            if not line:
                raise AssertionError(f"process exited ({proc.wait()}) before its line")
            if line.startswith("{"):
                return json.loads(line)
    raise AssertionError(f"no JSON line within {timeout_s:g} s")
