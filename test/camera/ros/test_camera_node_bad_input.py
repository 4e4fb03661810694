"""The camera node refuses to start without usable models, and --help works without ROS (real processes).

Malformed input at run time is tested in-process (test_camera_node.py).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

pytestmark = pytest.mark.ros

@pytest.mark.parametrize("content", [None, b"this is not an onnx model"])
def test_node_refuses_to_start_without_a_usable_model(
    ros_domain_id: int, tmp_path: Path, content: bytes | None
) -> None:
    model = tmp_path / "yunet.onnx"
    if content is not None:
        model.write_bytes(content)
    result = subprocess.run(
        [sys.executable, "-m", "face_reid_camera.ros.node", "--ros-args", "-p", f"detector_model_path:={model}"],
        env=procs.ros_env(ros_domain_id), cwd=procs.REPO, capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 2
    assert "FATAL: cannot start" in result.stderr
    assert str(model) in result.stderr
    assert "Traceback" not in result.stderr
    assert "Error:" not in result.stderr  # no class name (before: 'ModelLoadError: cannot load YuNet ONNX model')


def test_help_lists_the_deployment_parameters_and_help_all_every_one() -> None:
    from face_reid_camera.ros import params

    def shown(flag: str) -> str:
        result = subprocess.run([sys.executable, "-m", "face_reid_camera.ros.node", flag], cwd=procs.REPO,
                                capture_output=True, text=True, timeout=60, env=procs.ros_env(0))
        assert result.returncode == 0
        return result.stdout

    short, every = shown("--help"), shown("--help-all")
    for spec in params.TABLE.specs:
        assert f"  {spec.name} (default" in every
        assert (f"  {spec.name} (default" in short) == (params.TABLE.tier(spec.name) == "deployment"), spec.name
