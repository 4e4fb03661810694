"""Camera frames read from their CDR bytes: the same record as rclpy's message through frame_from_msg, and a
ValueError (nothing else) for bytes that are not a CameraFrame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.records import CameraFrameRecord
from face_reid_master.ros.convert import frame_from_msg
from face_reid_master.ros.frame_cdr import frame_from_cdr, is_plain_cdr

rclpy_serialization = pytest.importorskip("rclpy.serialization")
msgs = pytest.importorskip("face_reid_msgs.msg")

_TEXT = ["", "a", "ab", "abc", "abcd", "world", "cam_07", "kamera-ø", "✓✓", "x" * 9]


def _f32(rng: np.random.Generator, n: int) -> list[float]:
    values = rng.normal(size=n).astype(np.float32)
    if n and rng.random() < 0.2:
        values[rng.integers(n)] = np.nan
    return values.tolist()


def _frame(rng: np.random.Generator, people: int) -> object:
    msg = msgs.CameraFrame()
    msg.header.stamp.sec = int(rng.integers(-(2**31), 2**31))
    msg.header.stamp.nanosec = int(rng.integers(0, 10**9))
    msg.header.frame_id = str(rng.choice(_TEXT))
    msg.camera_id = str(rng.choice(_TEXT))
    msg.camera_frame_id = str(rng.choice(_TEXT))
    msg.camera_pose.position.x, msg.camera_pose.orientation.w = float(rng.normal()), float(rng.normal())
    msg.ground_plane_found = bool(rng.random() < 0.5)
    msg.processing_time_ms = float(np.float32(rng.random() * 50))
    msg.frames_dropped = int(rng.integers(0, 2**32))
    for _ in range(people):
        p = msgs.PersonObservation()
        p.position_world.x, p.position_world.y, p.position_world.z = (float(v) for v in rng.normal(size=3))
        p.position_camera.z = float(rng.normal())
        p.position_std_m, p.height_m = (float(np.float32(v)) for v in rng.random(2))
        p.num_points = int(rng.integers(0, 2**32))
        p.head_roi.x_offset, p.head_roi.do_rectify = int(rng.integers(0, 640)), bool(rng.random() < 0.5)
        p.face_found = bool(rng.random() < 0.7)
        p.face_score, p.face_quality, p.face_yaw_deg, p.face_eye_distance_px = _f32(rng, 4)
        p.face_box.width, p.face_box.do_rectify = int(rng.integers(0, 640)), bool(rng.random() < 0.5)
        p.embedding = _f32(rng, int(rng.choice([0, 1, 3, 128, 256])))
        p.embedding_space = str(rng.choice(_TEXT))
        if rng.random() < 0.7:
            p.body_descriptor = _f32(rng, int(rng.choice([0, 2, 128])))
            p.body_descriptor_space = str(rng.choice(_TEXT))
            p.body_visible_fraction = float(rng.choice([0.0, 0.5, math.nan]))
            p.body_part_visible = _f32(rng, int(rng.integers(0, 5)))
            (p.body_head_height_m, p.body_shoulder_width_m, p.body_torso_width_m, p.body_hip_width_m,
             p.body_torso_depth_m) = _f32(rng, 5)  # distinct values: a swapped field shows
            p.body_part_widths_m = _f32(rng, int(rng.integers(0, 5)))
        msg.people.append(p)
    return msg


def _same(a: object, b: object) -> bool:
    """Equal records (arrays elementwise with NaN = NaN, also in dtype)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype
                and a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True)))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(_same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def test_the_record_is_the_one_rclpy_and_frame_from_msg_give() -> None:
    rng = np.random.default_rng(7)
    for k in range(300):
        msg = _frame(rng, k % 6)
        data = rclpy_serialization.serialize_message(msg)
        assert is_plain_cdr(data)
        record, processing_ms = frame_from_cdr(data)
        expected = frame_from_msg(rclpy_serialization.deserialize_message(data, msgs.CameraFrame))
        assert isinstance(record, CameraFrameRecord)
        assert _same(record, expected), (k, record, expected)
        assert processing_ms == msg.processing_time_ms


def test_a_body_less_face_less_person_reads_as_frame_from_msg_does() -> None:
    msg = msgs.CameraFrame()
    msg.people.append(msgs.PersonObservation())
    record, _ = frame_from_cdr(rclpy_serialization.serialize_message(msg))
    (person,) = record.people
    assert person.embedding is None and person.body is None
    assert person.embedding_space == "dlib_resnet_v1"  # a camera from before spaces were named


def test_bytes_that_are_not_a_camera_frame_raise_value_error_only() -> None:
    rng = np.random.default_rng(3)
    data = rclpy_serialization.serialize_message(_frame(rng, 3))
    for cut in range(len(data)):  # every truncation
        with pytest.raises(ValueError):
            frame_from_cdr(data[:cut])
    for _ in range(2000):  # random damage: a record or a ValueError, never another exception
        damaged = bytearray(data)
        for i in rng.integers(2, len(damaged), int(rng.integers(1, 8))):
            damaged[i] = int(rng.integers(0, 256))
        try:
            frame_from_cdr(bytes(damaged))
        except ValueError:
            pass
    huge = bytearray(data)
    huge[-4:] = b"\xff\xff\xff\xff"
    with pytest.raises(ValueError):
        frame_from_cdr(bytes(huge))
    with pytest.raises(ValueError, match="little-endian"):
        frame_from_cdr(b"\x00\x00\x00\x00" + data[4:])  # big endian: rclpy's to read
    assert not is_plain_cdr(b"\x00\x00\x00\x00" + data[4:])
