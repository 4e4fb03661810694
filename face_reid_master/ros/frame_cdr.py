"""A camera's CameraFrame read from its CDR bytes straight into the core's record.

The master takes camera messages raw and reads what the core needs with a few ``struct`` / ``np.frombuffer``
calls per person, where rclpy would build a rosidl object with every field (and convert each array) that
:func:`~face_reid_master.ros.convert.frame_from_msg` then copies into the record. The record equals that path's
(the tests compare both on random and hostile messages). Layout: plain CDR, little endian (what Fast DDS sends),
taken from the one definition of the message (:mod:`face_reid_camera.common.msg_layout`: every struct, padding
and the order of the fields read here); other encodings are for rclpy (:func:`is_plain_cdr`). Bytes that are not
a CameraFrame raise ValueError, never anything else.
"""

from __future__ import annotations

import struct

import numpy as np

from face_reid_camera.body.observation import GEOMETRY_MSG_FIELDS
from face_reid_camera.common.embedding_spaces import DLIB_SPACE as LEGACY_EMBEDDING_SPACE
from face_reid_camera.common.msg_layout import CAMERA_FRAME, ENCAPSULATION_LE, PERSON_OBSERVATION, Fixed, segments
from face_reid_master.records import BodyRecord, CameraFrameRecord, PersonRecord

__all__ = ["frame_from_cdr", "is_plain_cdr"]

_CDR_LE = ENCAPSULATION_LE[:2]  # encapsulation kind: plain CDR, little endian
_U32 = struct.Struct("<I")


def _fixed(*segs: object) -> tuple[Fixed, ...]:
    """The runs of fixed-size fields among a message's segments (the variable ones are read in the order the
    import-time check below pins)."""
    return tuple(s for s in segs if isinstance(s, Fixed))


# CameraFrame: stamp | frame_id, camera_id, camera_frame_id | pose (skipped) .. frames_dropped | people
_FRAME_SEGMENTS = segments(CAMERA_FRAME, skip=("camera_pose", "ground_plane_found", "frames_dropped"))
_STAMP, _AFTER_POSE = _fixed(*_FRAME_SEGMENTS)
# PersonObservation: head | embedding, embedding_space, body_descriptor, body_descriptor_space | visible fraction |
# body_part_visible | geometry | body_part_widths_m
_PERSON_SEGMENTS = segments(PERSON_OBSERVATION, skip=("position_camera", "num_points", "head_roi", "face_box",
                                                      "face_yaw_deg"))
_PERSON_HEAD, _VISIBLE, _GEOMETRY = _fixed(*_PERSON_SEGMENTS)
_VARIABLE = tuple(getattr(s, "name", None) for s in _FRAME_SEGMENTS + _PERSON_SEGMENTS)
if _VARIABLE != (None, "header.frame_id", "camera_id", "camera_frame_id", None, "people", None, "embedding",
                 "embedding_space", "body_descriptor", "body_descriptor_space", None, "body_part_visible", None,
                 "body_part_widths_m"):  # the definition changed: _read / _person must follow it
    raise ImportError(f"frame_cdr reads another CameraFrame layout than msg_layout defines: {_VARIABLE}")
_STAMP_SEC, _STAMP_NSEC = (_STAMP.index(n) for n in ("header.stamp.sec", "header.stamp.nanosec"))
_PROCESSING_MS = _AFTER_POSE.index("processing_time_ms")
_HEAD_FIELDS = ("position_world.x", "position_world.y", "position_world.z", "position_std_m", "height_m",
                "face_found", "face_score", "face_quality", "face_eye_distance_px")
if _PERSON_HEAD.names != _HEAD_FIELDS:  # unpacked in this order by _person
    raise ImportError(f"frame_cdr reads another PersonObservation head than msg_layout defines: {_PERSON_HEAD.names}")
_HEAD, _HEAD_ALIGN = _PERSON_HEAD.struct, _PERSON_HEAD.start_align
_GEOMETRY_ORDER = tuple(_GEOMETRY.index(name) + 1 if name != "height_m" else 0 for name in GEOMETRY_MSG_FIELDS)


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
    stamp = _STAMP.struct.unpack_from(b, 4)
    frame_id, o = _string(b, 4 + _STAMP.struct.size)
    camera_id, o = _string(b, o)
    _, o = _string(b, o)  # camera_frame_id
    o = _align(o, _AFTER_POSE.start_align)
    processing_ms = _AFTER_POSE.struct.unpack_from(b, o)[_PROCESSING_MS]
    count, o = _u32(b, o + _AFTER_POSE.struct.size)
    if count > (len(b) - o) // _HEAD.size:
        raise ValueError(f"{count} people do not fit in {len(b)} bytes")
    people = []
    for _ in range(count):
        person, o = _person(b, o)
        people.append(person)
    return CameraFrameRecord(camera_id, stamp[_STAMP_SEC] + stamp[_STAMP_NSEC] * 1e-9, tuple(people),
                             frame_id), processing_ms


def _person(b: memoryview, o: int) -> tuple[PersonRecord, int]:
    o = _align(o, _HEAD_ALIGN)
    wx, wy, wz, std, height, face_found, score, quality, eye = _HEAD.unpack_from(b, o)  # _HEAD_FIELDS
    embedding, o = _floats(b, o + _HEAD.size)
    space, o = _string(b, o)
    descriptor, o = _floats(b, o)
    body_space, o = _string(b, o)
    o = _align(o, _VISIBLE.start_align)
    (visible,) = _VISIBLE.struct.unpack_from(b, o)
    part_visible, o = _floats(b, o + _VISIBLE.struct.size)
    o = _align(o, _GEOMETRY.start_align)
    geometry5 = _GEOMETRY.struct.unpack_from(b, o)
    part_widths, o = _floats(b, o + _GEOMETRY.struct.size)
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
