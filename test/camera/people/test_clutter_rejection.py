"""Person confirmation by depth shape: person-sized clutter on a thin support (coat stands) is not a person,
people are; rendered scenes from three camera poses (the real desk frames are in test_person_detector.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.people.detector import PersonDetector, PersonDetectorConfig
from face_reid_master.sim.renderer import SyntheticPerson, clutter_object, render_scene

K = CameraIntrinsics(525.0, 525.0, 319.5, 239.5, 640, 480)
POSES = [CameraPose.from_xyz_rpy(0.0, 0.0, h, 0.0, math.radians(p), 0.0) for h, p in ((2.4, 22), (1.6, 8), (2.8, 30))]


def _detect(pose: CameraPose, config: PersonDetectorConfig | None = None, **scene: object):
    frame = render_scene(scene.get("people", []), K, pose, objects=scene.get("objects", ()),
                         floor_size_m=14.0, rng=np.random.default_rng(7))
    return PersonDetector(config, camera_pose=pose).detect_depth(frame.depth_mm.astype(np.float32) / 1000.0, K)


@pytest.mark.parametrize("pose", POSES, ids=["2.4m-22deg", "1.6m-8deg", "2.8m-30deg"])
def test_coat_stands_are_rejected_by_their_thin_support(pose: CameraPose) -> None:
    for dist, lateral in ((2.5, -0.6), (4.0, 0.5), (6.0, 0.0)):
        objects = clutter_object("coat_stand", dist, lateral)
        unchecked = _detect(pose, PersonDetectorConfig(min_support_width_m=0.0), objects=objects)
        assert len(unchecked.people) == 1, f"the coat stand at {dist} m should look like a person without the check"
        checked = _detect(pose, objects=objects)
        assert checked.people == [] and checked.num_thin_support == 1, f"coat stand at {dist} m, {lateral} m"


def test_people_of_any_heading_pass_the_support_check() -> None:
    """The check never removes a person the detector finds without it (36 views: 3 poses x 4 ranges x 3 people)."""
    rng = np.random.default_rng(3)
    found = 0
    for pose in POSES:
        for dist in (2.0, 3.0, 4.5, 6.0):
            for _ in range(3):
                person = SyntheticPerson(dist, float(rng.uniform(-0.6, 0.6)), height_m=float(rng.uniform(1.5, 1.95)),
                                         facing_rad=float(rng.uniform(-math.pi, math.pi)))
                unchecked = _detect(pose, PersonDetectorConfig(min_support_width_m=0.0), people=[person])
                checked = _detect(pose, people=[person])
                assert len(checked.people) == len(unchecked.people) and checked.num_thin_support == 0, person
                found += len(checked.people)
    assert found >= 30


def test_a_support_out_of_view_is_no_evidence() -> None:
    """At 1.5 m the coat stand's pole below 0.6 m is outside the image: nothing to check, so it is reported (the
    master's static-clutter rule is what removes it)."""
    result = _detect(POSES[0], objects=clutter_object("coat_stand", 1.5, 0.5))
    assert len(result.people) == 1 and result.num_thin_support == 0


def test_support_band_must_be_ordered() -> None:
    with pytest.raises(ValueError, match="support_band_low_m"):
        PersonDetectorConfig(support_band_low_m=0.7, support_band_high_m=0.6)


def test_a_wall_cut_by_the_image_border_is_not_a_head() -> None:
    """Empty rooms seen from 20 poses: where the frustum cuts a wall its crest looks like a head at the image
    border (the unchecked detector finds such phantoms); with the border margin nobody is found."""
    phantoms = found = cut = 0
    for floor in (12.0, 14.0):
        for h, pitch in ((2.4, 22), (1.6, 8), (2.8, 30), (2.2, 15), (2.0, 12)):
            for yaw in (0.0, 0.5):
                pose = CameraPose.from_xyz_rpy(0.0, 0.0, h, 0.0, math.radians(pitch), yaw)
                depth = render_scene([], K, pose, walls=True, floor_size_m=floor,
                                     rng=np.random.default_rng(7)).depth_mm.astype(np.float32) / 1000.0
                phantoms += len(PersonDetector(PersonDetectorConfig(head_image_margin_px=0.0), pose)
                                .detect_depth(depth, K).people)
                result = PersonDetector(camera_pose=pose).detect_depth(depth, K)
                found += len(result.people)
                cut += result.num_cut_by_border
    assert phantoms >= 3 and found == 0 and cut == phantoms
