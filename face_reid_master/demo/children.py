"""Child processes of a live run (demo, live evaluation, DDS tests): each in its own process group, on a private
ROS domain with discovery on loopback only, dying with the parent (Linux PR_SET_PDEATHSIG), stopped together.

No rclpy here: the children are plain ``python ARGS`` processes; the parent joins the domain itself.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import json
import os
import queue
import random
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["ChildProcess", "child_env", "read_events", "spawn", "start_child", "stop_children", "stop_processes"]


def _libc_prctl() -> Any:
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True).prctl
    except OSError:
        return None


_PRCTL = _libc_prctl()
_PR_SET_PDEATHSIG = 1


def _die_with_parent(parent_pid: int) -> Any:
    """preexec_fn: the child gets SIGTERM when its parent dies, even by SIGKILL (Linux), so nothing is orphaned."""
    def set_up() -> None:
        if _PRCTL is not None:
            _PRCTL(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        if os.getppid() != parent_pid:  # the parent died before prctl took effect
            os._exit(1)
    return set_up


@dataclass
class ChildProcess:
    """A child process (own process group), its log and, for children that talk (players), the events it printed."""

    name: str
    proc: subprocess.Popen[str]
    log_path: Path
    events: queue.Queue[dict[str, Any]] = field(default_factory=queue.Queue)

    def log_tail(self, lines: int = 15) -> str:
        try:
            text = self.log_path.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(f"    {line}" for line in text[-lines:])


MAX_DOMAIN_ID = 232  # the largest ROS_DOMAIN_ID (DDS ports above it overflow); 102-214 need few participants


def domain_id_for_run(given: int | None, environ: Mapping[str, str] = os.environ) -> int:
    """The ROS domain of a run: ``given`` (e.g. --domain-id), else the environment's ROS_DOMAIN_ID, else a
    random one in 1..100; ValueError (with the valid range) for an id outside 0..232 or a malformed one."""
    if given is None and environ.get("ROS_DOMAIN_ID", "").strip():
        text = environ["ROS_DOMAIN_ID"].strip()
        if not text.isdigit():
            raise ValueError(f"ROS_DOMAIN_ID must be an integer in 0..{MAX_DOMAIN_ID}, got {text!r}")
        given = int(text)
    if given is None:
        return random.randint(1, 100)
    if not 0 <= given <= MAX_DOMAIN_ID:
        raise ValueError(f"the ROS domain id must be in 0..{MAX_DOMAIN_ID}, got {given}")
    return given


def child_env(domain_id: int, run_id: str | None = None) -> dict[str, str]:
    """Environment of a child: the given ROS domain, discovery on loopback only, this checkout importable and,
    with ``run_id``, ``FACE_REID_DEMO_RUN`` marking it as a child of that run."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env["PYTHONUNBUFFERED"] = "1"
    env["OMP_NUM_THREADS"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    if run_id is not None:
        env["FACE_REID_DEMO_RUN"] = run_id
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def spawn(args: list[str], env: dict[str, str], *, stdin: Any = None, stdout: Any = None, stderr: Any = None,
          cwd: Path | None = None) -> subprocess.Popen[str]:
    """``python ARGS`` (text streams as given) in its own process group, dying with this process.

    Start children before any thread of this process (``preexec_fn``).
    """
    return subprocess.Popen(
        [sys.executable, *args], env=env, stdin=stdin, stdout=stdout, stderr=stderr, cwd=cwd, text=True,
        start_new_session=True, preexec_fn=_die_with_parent(os.getpid()),
    )


def start_child(name: str, args: list[str], env: dict[str, str], log_dir: Path, talk: bool = False) -> ChildProcess:
    """:func:`spawn` with stderr (and stdout unless ``talk``: then stdin/stdout are pipes) to ``log_dir/NAME.log``."""
    log_path = log_dir / f"{name}.log"
    log = open(log_path, "w")  # handed to the child, closed below
    try:
        proc = spawn(args, env, stdin=subprocess.PIPE if talk else subprocess.DEVNULL,
                     stdout=subprocess.PIPE if talk else log, stderr=log)
    finally:
        log.close()
    return ChildProcess(name, proc, log_path)


def read_events(child: ChildProcess) -> None:
    """Thread: the player's JSON lines on stdout -> its event queue."""
    assert child.proc.stdout is not None
    for line in child.proc.stdout:
        line = line.strip()
        if line.startswith("{"):
            with contextlib.suppress(json.JSONDecodeError):
                child.events.put(json.loads(line))


def stop_processes(procs: Sequence[subprocess.Popen[str]], timeout_s: float = 5.0) -> None:
    """SIGINT every process group, then SIGKILL what is still there after ``timeout_s``."""
    for proc in procs:
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGINT)
    deadline = time.monotonic() + timeout_s
    for proc in procs:
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
    for proc in procs:
        if proc.poll() is None:  # still there (not reaped: its pid, the group id, cannot have been reused)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=2.0)


def stop_children(children: Sequence[ChildProcess], timeout_s: float = 5.0) -> None:
    """:func:`stop_processes` of the children, then close the pipes to them."""
    stop_processes([child.proc for child in children], timeout_s)
    for child in children:
        for stream in (child.proc.stdin, child.proc.stdout):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()
