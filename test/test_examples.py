"""The README's consumer example runs as written: it prints who is where from /tracks_named and follows the
rules a robot should (tentative tracks ignored, face_id 0 unknown, lost tracks marked as predictions)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import REPO_ROOT

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

pytestmark = pytest.mark.ros

EXAMPLE = REPO_ROOT / "examples" / "who_is_where.py"


def test_the_robots_page_shows_the_example_verbatim() -> None:
    assert f"```python\n{EXAMPLE.read_text()}```" in (REPO_ROOT / "docs" / "robots.md").read_text()


@pytest.mark.parametrize("secured", [False, True], ids=["plain", "with_key"])
def test_who_is_where_prints_the_people_a_robot_may_act_on(ros_context, ros_domain_id: int, tmp_path,
                                                           secured: bool) -> None:
    """Plain tracks, and (README step 7: ``who_is_where.py 0 KEYFILE``) tracks sealed with the network key; the
    same message three times is printed once."""
    import rclpy.executors

    from face_reid_camera.common.ros.sealed import seal_message
    from face_reid_camera.common.sealing import Sealer, load_network_key, write_network_key
    from face_reid_master.demo.children import child_env
    from face_reid_master.tracks_auth import TRACKS_PURPOSE
    from face_reid_msgs.msg import NamedTrack, NamedTrackArray, Sealed

    ctx = ros_context()
    node = rclpy.create_node("tracks_source", context=ctx)
    key_args: list[str] = []
    if secured:
        key_path = write_network_key(tmp_path / "network.key")
        sealer = Sealer(load_network_key(key_path), "/face_reid_master", TRACKS_PURPOSE)
        key_args = [str(key_path)]
        pub = node.create_publisher(Sealed, "/tracks_named_sealed", 10)
    else:
        pub = node.create_publisher(NamedTrackArray, "/tracks_named", 10)
    msg = NamedTrackArray()
    msg.header.frame_id = "world"
    for track_id, face_id, name, state, x in ((1, 0, "", NamedTrack.STATE_TENTATIVE, 0.5),
                                              (2, 7, "alice", NamedTrack.STATE_CONFIRMED, 1.25),
                                              (3, 0, "", NamedTrack.STATE_LOST, -2.0)):
        t = NamedTrack(track_id=track_id, face_id=face_id, name=name, state=state, identity_confidence=0.98,
                       identity_evidence="face" if face_id else "")
        t.position.x, t.position.y = x, 3.0
        msg.tracks.append(t)
    proc = subprocess.Popen([sys.executable, str(EXAMPLE), "3", *key_args], env=child_env(ros_domain_id), cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        # a barrier: publish until the example has read three messages and exited
        while proc.poll() is None:
            if pub.get_subscription_count() > 0:
                pub.publish(seal_message(sealer, msg) if secured else msg)
            executor.spin_once(timeout_sec=0.2)
        out = proc.stdout.read() if proc.stdout else ""
    finally:
        if proc.poll() is None:
            proc.kill()
        executor.shutdown()
        node.destroy_node()
    assert proc.returncode == 0, out
    assert out.count("2 people in 'world':") == 1, out  # three messages saying the same: printed once
    assert "track 2: alice at (1.25, 3.00) m; identity 0.98 by face" in out
    assert "track 3: someone unknown at (-2.00, 3.00) m, predicted (not seen for a while); identity no identity yet" \
        in out
    assert "track 1" not in out


@pytest.mark.parametrize("script", ["who_is_where.py", "diagnostics.py"])
def test_the_examples_run_as_commands_say_what_they_wait_for_and_end_cleanly_on_ctrl_c(
        script: str, ros_domain_id: int) -> None:
    """README step 7 runs them as commands; with nothing published they say once (stderr) what they wait for, and
    Ctrl-C is the normal way to end them: exit status 0, no traceback."""
    import os
    import signal

    from face_reid_master.demo.children import child_env

    path = REPO_ROOT / "examples" / script
    assert path.read_text().startswith("#!/usr/bin/env python3\n") and os.access(path, os.X_OK)
    proc = subprocess.Popen([sys.executable, str(path), *(["0"] if script == "who_is_where.py" else ["600"])],
                            env=child_env(ros_domain_id), cwd=REPO_ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None
        first = proc.stderr.readline()  # a barrier: the line comes once it listens (its Ctrl-C handler is set)
        assert "/tracks_named" in first or "/diagnostics" in first, first
        assert "Ctrl-C ends" in first and f"ROS_DOMAIN_ID={ros_domain_id}" in first, first
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert out == ""


def test_who_is_where_ends_cleanly_on_ctrl_c_while_tracks_arrive(ros_context, ros_domain_id: int) -> None:
    """A Ctrl-C while rclpy hands a message over used to surface as a pybind11 error (exit 1, traceback) about
    every second time: three runs, each interrupted right after its first message while tracks keep coming."""
    import os
    import signal

    import rclpy.executors

    from face_reid_master.demo.children import child_env
    from face_reid_msgs.msg import NamedTrack, NamedTrackArray

    ctx = ros_context()
    node = rclpy.create_node("tracks_source", context=ctx)
    pub = node.create_publisher(NamedTrackArray, "/tracks_named", 10)
    msg = NamedTrackArray(tracks=[NamedTrack(track_id=k, face_id=k, name=f"p{k}", state=NamedTrack.STATE_CONFIRMED)
                                  for k in range(1, 31)])
    executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        for _ in range(3):
            proc = subprocess.Popen([sys.executable, str(EXAMPLE), "0"], env=child_env(ros_domain_id), cwd=REPO_ROOT,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            try:
                assert proc.stdout is not None
                os.set_blocking(proc.stdout.fileno(), False)
                out = b""
                while b"people in" not in out and proc.poll() is None:  # a barrier: its first message printed
                    pub.publish(msg)
                    executor.spin_once(timeout_sec=0.002)
                    try:
                        out += os.read(proc.stdout.fileno(), 65536)
                    except BlockingIOError:
                        pass
                proc.send_signal(signal.SIGINT)
                while proc.poll() is None:  # tracks keep coming while it ends
                    pub.publish(msg)
                    executor.spin_once(timeout_sec=0.002)
                err = proc.communicate(timeout=60)[1].decode(errors="replace")
            finally:
                if proc.poll() is None:
                    proc.kill()
            assert proc.returncode == 0 and "Traceback" not in err and "Error" not in err, err
    finally:
        executor.shutdown()
        node.destroy_node()


def test_who_is_where_without_the_key_on_a_secured_network_says_how_to_give_it(ros_context,
                                                                               ros_domain_id: int) -> None:
    """A secured master's sealed tracks topic exists: the example, run without KEYFILE, says that the tracks are
    sealed and that the key file is its KEYFILE argument (a node's network_key_path means nothing to its user)."""
    import signal
    import time

    import rclpy

    from face_reid_master.demo.children import child_env
    from face_reid_msgs.msg import Sealed

    node = rclpy.create_node("secured_master_stand_in", context=ros_context())
    node.create_publisher(Sealed, "/tracks_named_sealed", 10)  # its topic in the graph is what the example checks
    proc = subprocess.Popen([sys.executable, str(EXAMPLE)], env=child_env(ros_domain_id), cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    said: list[str] = []
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 120.0  # a barrier: read its lines until it says the tracks are sealed
        while time.monotonic() < deadline and not any("tracks are sealed" in line for line in said):
            line = proc.stderr.readline()
            if not line:
                break
            said.append(line)
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
    sealed = [line for line in said if "tracks are sealed" in line]
    assert sealed and "who_is_where.py 0 KEYFILE" in sealed[0], said  # before: "set network_key_path"
    assert "network_key_path" not in sealed[0] and proc.returncode == 0


def test_who_is_where_names_an_unusable_key_file_in_one_line(tmp_path, ros_domain_id: int) -> None:
    from face_reid_master.demo.children import child_env

    run = subprocess.run([sys.executable, str(EXAMPLE), "0", str(tmp_path / "nope.key")],
                         env=child_env(ros_domain_id),
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and run.stderr.startswith("who_is_where: network key ") and "Traceback" not in \
        run.stderr, run.stderr
