"""A camera's CameraFrame read from its CDR bytes straight into the core's record.

The master takes camera messages raw and reads what the core needs with a few ``struct`` / ``np.frombuffer``
calls per person, where rclpy would build a rosidl object with every field (and convert each array) that
:func:`~face_reid_master.ros.convert.frame_from_msg` then copies into the record. The record equals that path's
(the tests compare both on random and hostile messages). Layout: plain CDR, little endian (what Fast DDS sends),
each primitive aligned to its size from the end of the 4-byte encapsulation header; other encodings are for
rclpy (:func:`is_plain_cdr`). Bytes that are not a CameraFrame raise ValueError, never anything else.
"""

from __future__ import annotations

import struct

import numpy as np

from face_reid_camera.body.observation import GEOMETRY_MSG_FIELDS
from face_reid_camera.common.embedding_spaces import DLIB_SPACE as LEGACY_EMBEDDING_SPACE
from face_reid_master.records import BodyRecord, CameraFrameRecord, PersonRecord

__all__ = ["frame_from_cdr", "is_plain_cdr"]

_CDR_LE = b"\x00\x01"  # encapsulation kind: plain CDR, little endian
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time
_AFTER_POSE = struct.Struct("<?3xfI")  # ground_plane_found, processing_time_ms, frames_dropped (8-aligned start)
_PERSON_HEAD = struct.Struct("<3d3dffI17x?2xf17x3xfff")  # positions .. face_eye_distance_px (from an 8-aligned start)
_F32 = struct.Struct("<f")
_GEOMETRY_5 = struct.Struct("<5f")  # body_head_height_m .. body_torso_depth_m, in message order
_MSG_GEOMETRY = ("body_head_height_m", "body_shoulder_width_m", "body_torso_width_m", "body_hip_width_m",
                 "body_torso_depth_m")
_GEOMETRY_ORDER = tuple(_MSG_GEOMETRY.index(name) + 1 if name != "height_m" else 0 for name in GEOMETRY_MSG_FIELDS)
_POSE_BYTES = 56  # geometry_msgs/Pose: 7 float64


def is_plain_cdr(data: bytes) -> bool:
    """Whether ``data`` is encoded as :func:`frame_from_cdr` reads (plain CDR, little endian)."""
    return data[:2] == _CDR_LE


def frame_from_cdr(data: bytes) -> tuple[CameraFrameRecord, float]:
    """The record of a serialized face_reid_msgs/CameraFrame (no validation: the core validates and counts) and
    the camera's ``processing_time_ms``. ValueError when ``data`` is not one (truncated, bad lengths, strings
    that are not UTF-8, another encoding)."""
    if not is_plain_cdr(data):
        raise ValueError("not a little-endian plain-CDR message")
    try:
        return _read(memoryview(data))
    except (struct.error, IndexError, UnicodeDecodeError, OverflowError) as exc:
        raise ValueError(f"malformed CameraFrame CDR ({len(data)} bytes): {exc}") from exc


def _read(b: memoryview) -> tuple[CameraFrameRecord, float]:
    sec, nanosec = _STAMP.unpack_from(b, 4)
    frame_id, o = _string(b, 12)
    camera_id, o = _string(b, o)
    _, o = _string(b, o)  # camera_frame_id
    o = _align(o, 8) + _POSE_BYTES
    _, processing_ms, _ = _AFTER_POSE.unpack_from(b, o)
    count, o = _u32(b, o + _AFTER_POSE.size)
    if count > (len(b) - o) // _PERSON_HEAD.size:
        raise ValueError(f"{count} people do not fit in {len(b)} bytes")
    people = []
    for _ in range(count):
        person, o = _person(b, o)
        people.append(person)
    return CameraFrameRecord(camera_id, sec + nanosec * 1e-9, tuple(people), frame_id), processing_ms


def _person(b: memoryview, o: int) -> tuple[PersonRecord, int]:
    o = _align(o, 8)
    (wx, wy, wz, _, _, _, std, height, _, face_found, score, quality, _, eye) = _PERSON_HEAD.unpack_from(b, o)
    embedding, o = _floats(b, o + _PERSON_HEAD.size)
    space, o = _string(b, o)
    descriptor, o = _floats(b, o)
    body_space, o = _string(b, o)
    o = _align(o, 4)
    (visible,) = _F32.unpack_from(b, o)
    part_visible, o = _floats(b, o + 4)
    o = _align(o, 4)
    geometry5 = _GEOMETRY_5.unpack_from(b, o)
    part_widths, o = _floats(b, o + _GEOMETRY_5.size)
    body = None
    if descriptor.size or visible:  # as frame_from_msg: a camera from before bodies sends neither
        values = (height, *geometry5)
        body = BodyRecord(descriptor, body_space, visible,
                          np.array([values[k] for k in _GEOMETRY_ORDER], dtype=np.float32), part_visible, part_widths)
    person = PersonRecord(np.array([wx, wy, wz]), std, height, embedding if face_found and embedding.size else None,
                          score, quality, space or LEGACY_EMBEDDING_SPACE, eye, body)
    return person, o


def _align(o: int, size: int) -> int:
    return o + (-(o - 4) % size)


def _u32(b: memoryview, o: int) -> tuple[int, int]:
    o = _align(o, 4)
    return _U32.unpack_from(b, o)[0], o + 4


def _string(b: memoryview, o: int) -> tuple[str, int]:
    n, o = _u32(b, o)
    if n == 0 or o + n > len(b) or b[o + n - 1] != 0:
        raise ValueError(f"a string of length {n} at byte {o} is not NUL-terminated within the message")
    return str(b[o:o + n - 1], "utf-8"), o + n


def _floats(b: memoryview, o: int) -> tuple[np.ndarray, int]:
    n, o = _u32(b, o)
    if 4 * n > len(b) - o:
        raise ValueError(f"{n} float32 values at byte {o} do not fit in {len(b)} bytes")
    return np.frombuffer(b, "<f4", n, o).astype(np.float32), o + 4 * n
