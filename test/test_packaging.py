"""Packaging: the pip install made the suite reachable the ROS way, and face_reid_msgs builds with colcon."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import colcon_build

REPO = Path(__file__).resolve().parents[1]
PREFIX = Path(sys.prefix)


def _installed_non_editable() -> bool:
    return (PREFIX / "share" / "ament_index" / "resource_index" / "packages" / "face_reid_msgs").exists()


@pytest.mark.skipif(not _installed_non_editable(), reason="face-reid is not pip-installed in this environment")
def test_ros2_run_entry_points_and_data_are_installed() -> None:
    index = PREFIX / "share" / "ament_index" / "resource_index" / "packages"
    for pkg, exes in {
        "face_reid_camera": ["face-reid-camera", "face-reid-replay", "face-reid-keys", "face-reid-state"],
        "face_reid_master": ["face-reid-master", "face-reid-faces", "face-reid-calibrate", "face-reid-up",
                             "face-reid-goto", "face-reid-map", "face-reid-align-map"],
    }.items():
        assert (index / pkg).exists()
        for exe in exes:
            wrapper = PREFIX / "lib" / pkg / exe
            assert wrapper.exists() and os.access(wrapper, os.X_OK), wrapper
            assert (PREFIX / "bin" / exe).exists(), f"console script {exe} missing"
    models = PREFIX / "share" / "face_reid" / "models"
    assert (models / "dlib_face_recognition_resnet_model_v1.onnx").exists()
    assert (models / "face_detection_yunet_2023mar_dynamic.onnx").exists()
    # every model file of the checkout is installed (the body projection .npz was not: cameras with bodies on
    # failed outside a checkout)
    shipped = {p.name for p in (REPO / "models").iterdir() if p.suffix in (".onnx", ".json", ".npz")}
    assert shipped <= {p.name for p in models.iterdir()}, shipped - {p.name for p in models.iterdir()}
    assert (PREFIX / "share" / "face_reid" / "config" / "camera.yaml").exists()


@pytest.mark.skipif(not _installed_non_editable(), reason="face-reid is not pip-installed in this environment")
def test_wrapper_runs_the_console_script() -> None:
    result = subprocess.run(
        [str(PREFIX / "lib" / "face_reid_camera" / "face-reid-replay"), "--help"],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0 and "face-reid-replay" in result.stdout


@pytest.mark.skipif(not _installed_non_editable(), reason="face-reid is not pip-installed in this environment")
def test_installed_master_loads_the_installed_likelihood(tmp_path: Path) -> None:
    """Outside the checkout the installed packages find the default space's models/face_likelihood_<space>.json in
    <prefix>/share."""
    probe = (
        "import json, face_reid_master\n"
        "from face_reid_camera.common.resources import model_path\n"
        "from face_reid_master.core import MasterConfig, MasterCore\n"
        "from face_reid_master.identity.size_likelihood import default_likelihood_file\n"
        "core = MasterCore()\n"
        "path = model_path(default_likelihood_file(MasterConfig().embedding_space))\n"
        "print(json.dumps({'package': face_reid_master.__file__, 'path': str(path),\n"
        "                  'decision': core.identity.likelihood.decision_distance}))\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("FACE_REID_") and k != "PYTHONPATH"}
    result = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    import json

    from face_reid_master.identity.size_likelihood import load_face_likelihood

    got = json.loads(result.stdout)
    assert Path(got["package"]).is_relative_to(PREFIX), "the probe must import the installed copy"
    name = "face_likelihood_dlib_resnet_v1+sface_2021dec.json"  # the default master's joint space
    assert Path(got["path"]) == PREFIX / "share" / "face_reid" / "models" / name
    shipped = load_face_likelihood(REPO / "models" / name)
    assert got["decision"] == pytest.approx(shipped.decision_distance, abs=1e-12)


@pytest.mark.slow
def test_face_reid_msgs_builds_with_colcon(tmp_path: Path) -> None:
    src = tmp_path / "ws" / "src"
    shutil.copytree(REPO / "face_reid_msgs", src / "face_reid_msgs")
    colcon_build(tmp_path / "ws", timeout_s=600)
    generated = list((tmp_path / "ws" / "install" / "face_reid_msgs").rglob("_named_track_array.py"))
    assert generated, "no generated Python message module"
