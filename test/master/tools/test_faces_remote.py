"""face-reid-faces --master: list / add / forget through a running (secured) master's services, over real DDS
(the master in this process, the command-line tool as its own process, loopback)."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import pytest
from conftest import FACES_DIR, REPO_ROOT
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn

from face_reid_camera.common.sealing import write_network_key
from face_reid_master.ros.node import MasterNode
from face_reid_master.tools.faces_remote import refusal_line


def _start_master(ctx) -> tuple[MasterNode, SingleThreadedExecutor, threading.Thread]:
    master = MasterNode(context=ctx)
    assert master.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert master.trigger_activate() == TransitionCallbackReturn.SUCCESS
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(master)
    spinning = threading.Thread(target=executor.spin, daemon=True)
    spinning.start()
    return master, executor, spinning


def _stop_master(master: MasterNode, executor: SingleThreadedExecutor, spinning: threading.Thread) -> None:
    executor.shutdown()
    spinning.join(timeout=10)
    if master.core is not None:  # as a stopped master leaves it: the store closed
        master.trigger_deactivate()
        master.trigger_cleanup()
    master.destroy_node()


def test_a_refusal_is_one_line_with_its_reason_once_and_the_key_hint_when_no_key_was_given() -> None:
    unsealed = "refused: this node has a network key: requests must be sealed with it"  # the master's reply
    assert refusal_line("face-reid-faces", unsealed, keyed=False) == (  # before: "refused: refused: ..."
        "face-reid-faces: refused: this node has a network key: requests must be sealed with it (give --key with "
        "the network's key file)")
    assert refusal_line("face-reid-faces", "no such face or person", keyed=True) == \
        "face-reid-faces: refused: no such face or person"


@pytest.mark.slow
def test_list_add_forget_on_a_running_secured_master(ros_domain_id: int, ros_context, tmp_path: Path) -> None:
    key = write_network_key(tmp_path / "network.key")
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={key}", "-p", "admin_services:=true",
                       "-p", "body_appearance_tracking:=false"])
    running = _start_master(ctx)
    master = running[0]

    def faces(*args: str, timeout: float = 90.0) -> subprocess.CompletedProcess[str]:  # a cap: a reply ends it
        return subprocess.run([sys.executable, "-m", "face_reid_master.tools.faces_cli", "--master",
                               "/face_reid_master", "--timeout-s", str(timeout), *args], cwd=REPO_ROOT,
                              env=procs.ros_env(ros_domain_id), capture_output=True, text=True, timeout=180)

    try:
        photos = [str(p) for p in sorted((FACES_DIR / "deepface_id01").glob("*.jpg"))[:3]]
        run = faces("--key", str(key), "add", "Alice", *photos, "--space", "dlib_resnet_v1")
        assert run.returncode == 0 and "added Alice with 3 embeddings" in run.stdout, run.stderr
        assert master.core.people.names() == ["Alice"]
        run = faces("list")  # no key: a secured master lists nothing, and the tool says why
        assert run.returncode == 0 and "0 face(s) on /face_reid_master" in run.stdout
        assert "answers a listing without --key with nothing" in run.stderr, run.stderr
        run = faces("list", "--key", str(key), "--timeout-s", "90")  # options after the command too
        assert run.returncode == 0 and "on /face_reid_master" in run.stdout, run.stderr
        assert "1 predefined person(s)" in run.stdout and any(  # before: "0 face(s)" and no Alice anywhere
            line.split() == ["Alice", "3"] for line in run.stdout.splitlines()), run.stdout
        assert master.admin.refusals["list_faces"] == 1 and master.admin.calls["list_faces"] == 2
        run = faces("add", "Mallory", *photos, "--space", "dlib_resnet_v1")  # no key: a secured master refuses
        assert run.returncode == 1 and "must be sealed" in run.stderr and master.core.people.names() == ["Alice"]
        assert "refused: refused" not in run.stderr and "give --key" in run.stderr, run.stderr
        _stop_master(*running)  # a restart (face-reid-up restarts a master on its own): Alice is still known
        running = _start_master(ctx)
        master = running[0]
        assert master.core.people.names() == ["Alice"]  # before: 0 predefined people
        run = faces("--key", str(key), "list")
        assert run.returncode == 0 and "1 predefined person(s)" in run.stdout, run.stdout + run.stderr
        run = faces("--key", str(key), "forget", "--name", "Alice")
        assert run.returncode == 0 and "removed the predefined person 'Alice'" in run.stdout, run.stderr
        assert master.core.people.names() == []
        _stop_master(*running)  # forgotten for good: not back after a restart
        running = _start_master(ctx)
        master = running[0]
        assert master.core.people.names() == [] and master.store.load_people() == {}
        assert faces("rename", "1", "Bob").returncode == 2
        nobody = subprocess.run([sys.executable, "-m", "face_reid_master.tools.faces_cli", "--master", "/nobody",
                                 "--timeout-s", "2", "list"], cwd=REPO_ROOT, env=procs.ros_env(ros_domain_id),
                                capture_output=True, text=True, timeout=60)
        assert nobody.returncode == 5 and "no service /nobody/list_faces" in nobody.stderr
    finally:
        _stop_master(*running)
