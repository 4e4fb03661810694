"""face-reid-state's lines: the outcome (the state said once), and a secured node asked without --key."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import REPO_ROOT

from face_reid_camera.tools.state import outcome_line, unreachable_line


def test_get_says_the_state_once_and_a_transition_says_where_it_ended() -> None:
    # before: '/face_reid_master: state active (state active)'
    assert outcome_line("/face_reid_master", "state active", "active") == "/face_reid_master: state active"
    assert outcome_line("/n", "configure: done", "inactive") == "/n: configure: done (state inactive)"
    assert outcome_line("/n", "refused: not sealed", "") == "/n: refused: not sealed"


def test_a_secured_node_asked_without_the_key_is_named_as_secured() -> None:
    services = ["/face_reid_master/change_state_sealed", "/face_reid_master/list_faces"]
    assert unreachable_line("no service /face_reid_master/get_state within 20 s (...)", "/face_reid_master",
                            services, keyed=False) == ("face-reid-state: /face_reid_master is secured (it offers only "
                                                       "change_state_sealed): give --key with the network's key file")
    assert unreachable_line("no service /n/get_state within 20 s", "/n", [], keyed=False) == \
        "face-reid-state: no service /n/get_state within 20 s"
    assert unreachable_line("no reply", "/face_reid_master", services, keyed=True) == "face-reid-state: no reply"


@pytest.mark.slow  # the tool waits its whole --timeout-s
@pytest.mark.ros
def test_the_tool_without_key_names_a_secured_node(ros_context, ros_domain_id: int) -> None:
    """Before: 'no service /secured/get_state within 30 s (is the node running ..., and secured exactly when --key
    is given?)', while the node ran, secured."""
    import rclpy

    from face_reid_master.demo.children import child_env
    from face_reid_msgs.srv import ChangeState

    node = rclpy.create_node("secured", context=ros_context())
    node.create_service(ChangeState, "/secured/change_state_sealed", lambda request, response: response)
    try:  # 30 s: time for discovery on a loaded machine (the tool reads the graph once its wait is over)
        run = subprocess.run([sys.executable, "-m", "face_reid_camera.tools.state", "/secured", "get",
                              "--timeout-s", "30"], cwd=REPO_ROOT, env=child_env(ros_domain_id),
                             capture_output=True, text=True, timeout=120)
    finally:
        node.destroy_node()
    assert run.returncode == 5 and run.stderr.strip() == (
        "face-reid-state: /secured is secured (it offers only change_state_sealed): give --key with the network's "
        "key file"), run.stderr
