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


def test_who_is_where_prints_the_people_a_robot_may_act_on(ros_context, ros_domain_id: int) -> None:
    import rclpy.executors

    from face_reid_master.demo.children import child_env
    from face_reid_msgs.msg import NamedTrack, NamedTrackArray

    ctx = ros_context()
    node = rclpy.create_node("tracks_source", context=ctx)
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
    proc = subprocess.Popen([sys.executable, str(EXAMPLE), "1"], env=child_env(ros_domain_id), cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        # a barrier: publish until the example has printed its one message and exited
        while proc.poll() is None:
            if pub.get_subscription_count() > 0:
                pub.publish(msg)
            executor.spin_once(timeout_sec=0.2)
        out = proc.stdout.read() if proc.stdout else ""
    finally:
        if proc.poll() is None:
            proc.kill()
        executor.shutdown()
        node.destroy_node()
    assert proc.returncode == 0, out
    assert "2 people in 'world':" in out
    assert "track 2: alice at (1.25, 3.00) m; identity 0.98 by face" in out
    assert "track 3: someone unknown at (-2.00, 3.00) m, predicted (not seen for a while); identity no identity yet" \
        in out
    assert "track 1" not in out
