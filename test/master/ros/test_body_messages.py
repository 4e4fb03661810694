"""The body fields of PersonObservation: camera core -> message -> master record, and messages without them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_camera.body.observation import GEOMETRY_FIELDS, BodyGeometry, BodyObservation
from face_reid_camera.pipeline import PersonObservation
from face_reid_master.records import BodyRecord, CameraFrameRecord, PersonRecord

pytest.importorskip("face_reid_msgs.msg")


def _camera_person(body: BodyObservation | None) -> PersonObservation:
    return PersonObservation(np.array([1.0, 2.0, 0.0]), np.array([0.1, 0.2, 3.0]), 0.05, 1.71, 120, None, None, body)


def test_a_camera_body_arrives_as_a_master_record() -> None:
    from face_reid_camera.ros.convert import person_to_msg
    from face_reid_master.ros.convert import frame_from_msg
    from face_reid_msgs.msg import CameraFrame
    from face_reid_msgs.msg import PersonObservation as PersonMsg

    geometry = BodyGeometry(1.71, 0.26, 0.41, 0.38, 0.14, float("nan"), (0.4, 0.38, 0.3, 0.25))
    body = BodyObservation(np.arange(12, dtype=np.float32) / 10, "body_pca_hsv8_siltp4_0123abcd", 0.8,
                           (1.0, 1.0, 0.7, 0.5), geometry)
    frame = CameraFrame()
    frame.camera_id = "c"
    frame.header.frame_id = "world"
    frame.people = [person_to_msg(PersonMsg, _camera_person(body)), person_to_msg(PersonMsg, _camera_person(None))]
    record = frame_from_msg(frame)
    got = record.people[0].body
    assert isinstance(got, BodyRecord)
    assert np.array_equal(got.descriptor, body.descriptor) and got.space == body.space
    assert got.visible_fraction == pytest.approx(0.8)
    assert np.allclose(got.part_visible, body.part_visible)
    # geometry in GEOMETRY_FIELDS order; the height is the detection's own height_m; NaN stays NaN
    expected = geometry.vector()
    assert GEOMETRY_FIELDS[0] == "height_m" and got.geometry.shape == (len(GEOMETRY_FIELDS),)
    assert np.allclose(got.geometry[:5], expected[:5]) and math.isnan(got.geometry[5])
    assert np.allclose(got.part_widths_m, geometry.part_widths_m)
    assert record.people[1].body is None  # a person the camera did not describe


def test_frames_of_cameras_without_bodies_have_none_and_replays_keep_bodies() -> None:
    from face_reid_master.ros.convert import frame_from_msg, frame_record_to_msg

    old = frame_record_to_msg(CameraFrameRecord("c", 5.0, (PersonRecord(np.array([0.0, 1.0, 0.0])),)), 5.0)
    assert list(old.people[0].body_descriptor) == [] and old.people[0].body_visible_fraction == 0.0
    assert frame_from_msg(old).people[0].body is None
    body = BodyRecord(np.full(6, 0.5, np.float32), "body_pca_hsv4_siltp2_00000000", 0.6,
                      np.array([1.8, 0.25, 0.42, 0.4, 0.12, 0.36], np.float32), np.array([1, 1, 0.5, 0], np.float32),
                      np.array([0.4, 0.38, 0.3, np.nan], np.float32))
    new = frame_record_to_msg(CameraFrameRecord("c", 5.0, (PersonRecord(np.array([0.0, 1.0, 0.0]), height_m=1.8,
                                                                        body=body),)), 5.0)
    back = frame_from_msg(new).people[0].body
    assert back is not None and np.array_equal(back.descriptor, body.descriptor) and back.space == body.space
    assert np.allclose(back.geometry, body.geometry) and np.allclose(back.part_visible, body.part_visible)
    assert np.allclose(back.part_widths_m, body.part_widths_m, equal_nan=True)
    # geometry only (no descriptor): still a body, with no space
    geometry_only = BodyRecord(np.zeros(0, np.float32), "", 0.4, body.geometry)
    msg = frame_record_to_msg(CameraFrameRecord("c", 5.0, (PersonRecord(np.array([0.0, 1.0, 0.0]), height_m=1.8,
                                                                        body=geometry_only),)), 5.0)
    back = frame_from_msg(msg).people[0].body
    assert back is not None and back.descriptor.size == 0 and back.visible_fraction == pytest.approx(0.4)


def test_the_master_core_counts_bodies_and_rejects_malformed_ones_and_other_spaces() -> None:
    from face_reid_master.core import MasterConfig, MasterCore

    core = MasterCore(MasterConfig(embedding_space="dlib_resnet_v1"))
    good = BodyRecord(np.ones(4, np.float32), "s", 0.9, np.full(6, np.nan, np.float32))
    nan = BodyRecord(np.array([1.0, np.nan], np.float32), "s", 0.9, np.full(6, np.nan, np.float32))
    bad_visible = BodyRecord(np.ones(4, np.float32), "s", 1.5, np.full(6, np.nan, np.float32))
    people = tuple(PersonRecord(np.array([float(i), 0.0, 0.0]), body=b) for i, b in
                   enumerate((good, nan, bad_visible, None)))
    outcome = core.process_frame(CameraFrameRecord("c", 1.0, people), now_s=1.0)
    assert outcome.accepted and len(outcome.track_of_person) == 4  # every person tracked, bodies or not
    assert core.stats.bodies_received == 1 and core.stats.bodies_rejected_malformed == 2
    # the good body is of another projection than the shipped metric's: counted, said once, not used
    assert core.stats.bodies_rejected_space == 1
    assert len(outcome.notices) == 1 and "'c'" in outcome.notices[0] and "'s'" in outcome.notices[0]
    again = core.process_frame(CameraFrameRecord("c", 1.1, people), now_s=1.1)
    assert core.stats.bodies_rejected_space == 2 and not again.notices
