"""The camera parameter table, config/camera.yaml and the pipeline config agree."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO_ROOT

from face_reid_camera.ros import params

CONFIG = REPO_ROOT / "config" / "camera.yaml"


def test_config_yaml_gives_the_defaults() -> None:
    assert params.load_params_yaml(CONFIG) == params.defaults()


def test_every_parameter_is_described_with_care() -> None:
    names = params.TABLE.names()
    assert len(names) == len(set(names))
    for spec in params.TABLE.specs:
        assert len(spec.description) > 20, spec.name
        assert not spec.description.startswith("Person detector:"), f"{spec.name} has no real description"


def test_defaults_build_a_valid_pipeline_config() -> None:
    config = params.pipeline_config(params.defaults())
    assert config.head_roi_size_m == pytest.approx(0.3)
    pose = params.camera_pose(params.defaults())
    assert pose.translation[2] == pytest.approx(2.5)
    # pitch > 0 looks down: the optical axis has a negative world z component
    assert pose.rotation[2, 2] < 0


def test_overrides_nested_and_flat(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    camera_id: cam7\n    head_roi_size_m: 1.0\n"
        "    person:\n      voxel_size_m: 0.05\n"
    )
    values = params.load_params_yaml(path)
    assert values["camera_id"] == "cam7"
    assert values["head_roi_size_m"] == 1.0 and isinstance(values["head_roi_size_m"], float)
    assert params.pipeline_config(values).person.voxel_size_m == pytest.approx(0.05)


@pytest.mark.parametrize("body,match", [
    ("    detect_faces: 3\n", "detect_faces"),
    ("    camera_pose_xyz_m: [1.0, 2.0]\n", "camera_pose_xyz_m"),
    ("    head_roi_size_m: big\n", "head_roi_size_m"),
    ("    head_roi_size_m: 9.0\n", r"must be in \[0.05, 2\], got 9.0"),
    # what the node refuses (rcl's types), replay refuses too (before: read as 1.0 and [0.0, 0.0, 1.5])
    ("    head_roi_size_m: 1\n", r"'head_roi_size_m' must be a float like 0.3, got 1 \(write numbers with a decimal"),
    ("    camera_pose_xyz_m: [0, 0, 1.5]\n", r"a list mixing integers and floats \(\[0, 0, 1.5\]\) is refused by "
     r"ROS \(Sequence should be of same type\)"),
])
def test_bad_values_are_named(tmp_path: Path, body: str, match: str) -> None:
    path = tmp_path / "p.yaml"
    path.write_text("face_reid_camera:\n  ros__parameters:\n" + body)
    with pytest.raises(ValueError, match=match):
        params.load_params_yaml(path)


def test_invalid_value_ranges_fail_in_the_config() -> None:
    values = params.defaults()
    values["head_roi_size_m"] = -0.3
    with pytest.raises(ValueError, match="head_roi_size_m"):
        params.pipeline_config(values)


@pytest.mark.parametrize("body,match", [
    ("    no_such_param: 1\n", "'no_such_param' is not a parameter of face_reid_camera: ignored"),
    ("    person:\n      voxel_sise_m: 0.05\n", "did you mean 'person.voxel_size_m'"),
])
def test_unknown_names_are_warnings_as_on_the_node(tmp_path: Path, body: str, match: str) -> None:
    """The node ignores a name it does not declare (with a warning): so does the one loader (before: replay refused)."""
    from face_reid_camera.common.params_files import load_params_file

    path = tmp_path / "p.yaml"
    path.write_text("face_reid_camera:\n  ros__parameters:\n" + body)
    loaded = load_params_file(params.TABLE, path)
    assert loaded.values == params.defaults() and len(loaded.warnings) == 1 and match in loaded.warnings[0]
