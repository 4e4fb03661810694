"""A node name or namespace rcl refuses when the node is made (it passes the command-line parser: e.g. longer than
rmw allows) is one FATAL line and exit status 2, like any bad start, not a Python traceback with status 1."""

from __future__ import annotations

import pytest
from conftest import start_up_output

pytestmark = pytest.mark.ros

LONG = "a" * 300  # rmw: a node name of at most 255 characters


@pytest.mark.parametrize("module,prog,remap,expected", [
    ("face_reid_camera.ros.node", "face-reid-camera", f"__node:={LONG}", "invalid node name"),
    ("face_reid_camera.ros.node", "face-reid-camera", f"__ns:=/{LONG}", "invalid node namespace"),
    ("face_reid_master.ros.node", "face-reid-master", f"__node:={LONG}", "invalid node name"),
    ("face_reid_master.ros.map_node", "face-reid-map", f"__node:={LONG}", "invalid node name"),
    ("face_reid_master.ros.goto_node", "face-reid-goto", f"__node:={LONG}", "invalid node name"),
])
def test_a_node_name_rcl_refuses_is_one_fatal_line(ros_domain_id: int, module: str, prog: str, remap: str,
                                                   expected: str) -> None:
    status, lines = start_up_output(module, "-r", remap)
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"[{prog}] FATAL: cannot start: ") and expected in lines[0], lines
    assert ", at /" not in lines[0]  # rcl's source locations left out
