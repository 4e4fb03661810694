"""The /tracks_named message as CDR bytes, written directly from the core's tracks.

``Publisher.publish(bytes)`` sends them as they are, without the rosidl objects rclpy would build, convert and
serialize on every cycle; subscribers get the same message (the tests compare with rclpy's ``serialize_message``).
Layout: plain CDR, little endian (the encoding Fast DDS gives ROS 2 messages), each struct and padding derived from
the one definition of the message (:mod:`face_reid_camera.common.msg_layout`); the values are packed in its field
order.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.msg_layout import (
    ENCAPSULATION_LE,
    NAMED_TRACK,
    NAMED_TRACK_ARRAY,
    first_alignment,
    packing,
)
from face_reid_camera.common.stamps import seconds_to_stamp
from face_reid_master.records import NamedTrackRecord

__all__ = ["tracks_to_cdr"]

_FLOAT32_MAX = float(np.finfo(np.float32).max)
_U64 = 0xFFFF_FFFF_FFFF_FFFF
_F8 = np.dtype("<f8")
_TRACK_ALIGN = first_alignment(NAMED_TRACK)  # each NamedTrack starts aligned to its first field (a uint64: 8)


@lru_cache(maxsize=64)
def _head_layout(frame_id: int) -> struct.Struct:
    """The packing of the NamedTrackArray's header and its tracks' count, for a frame id of this byte length."""
    return packing(NAMED_TRACK_ARRAY, (frame_id, 0))


@lru_cache(maxsize=1024)
def _track_layout(name: int, evidence: int, cameras: tuple[int, ...]) -> struct.Struct:
    """The packing of one NamedTrack whose strings encode to these byte lengths, from an aligned start: the
    paddings depend only on them."""
    return packing(NAMED_TRACK, (name, evidence, len(cameras), *cameras))


def _float32(value: float) -> float:
    """What a C cast to float gives (struct refuses finite values beyond float32's range)."""
    if math.isfinite(value) and abs(value) > _FLOAT32_MAX:
        return math.copysign(math.inf, value)
    return value


def _stamp(stamp_s: float) -> tuple[int, int]:
    sec, nanosec = seconds_to_stamp(max(0.0, stamp_s))
    return min(sec, 2**31 - 1), nanosec


def _covariance(cov: NDArray[np.float64]) -> bytes:
    """The 16 float64 of a 4x4 covariance, little endian (the tracker's arrays already are: no conversion)."""
    if cov.dtype == _F8 and cov.size == 16 and cov.flags.c_contiguous:
        return cov.tobytes()
    return np.asarray(cov, dtype=_F8).reshape(16).tobytes()


def _xy0(xy: NDArray[np.float64]) -> tuple[float, float, float]:
    """A Point / Vector3 on the floor (z = 0) from an (x, y) array."""
    x, y = np.asarray(xy, dtype=np.float64).reshape(-1)[:2].tolist()
    return x, y, 0.0


def _utf8(text: str) -> bytes:
    return text.encode("utf-8", "replace")


def tracks_to_cdr(tracks: Sequence[NamedTrackRecord], stamp_s: float, frame_id: str) -> bytes:
    """The serialized face_reid_msgs/NamedTrackArray of ``tracks`` stamped ``stamp_s`` in ``frame_id``: the same
    message as :func:`face_reid_master.ros.convert.tracks_to_msg` gives."""
    frame = _utf8(frame_id)
    head = _head_layout(len(frame)).pack(*_stamp(stamp_s), len(frame) + 1, frame, len(tracks))
    pieces = [ENCAPSULATION_LE, head]
    offset = len(head)  # from the end of the encapsulation header
    for tr in tracks:
        name, evidence = _utf8(tr.name), _utf8(tr.identity_evidence)
        cameras = [_utf8(c) for c in tr.cameras]
        if gap := -offset % _TRACK_ALIGN:
            pieces.append(bytes(gap))
            offset += gap
        layout = _track_layout(len(name), len(evidence), tuple(len(c) for c in cameras))
        height = float(tr.height_m)
        strings = [v for c in cameras for v in (len(c) + 1, c)]
        data = layout.pack(
            int(tr.track_id) & _U64, int(tr.face_id) & _U64, len(name) + 1, name,
            _float32(float(tr.identity_confidence)), min(max(int(tr.face_observations), 0), 0xFFFF_FFFF),
            len(evidence) + 1, evidence,
            *_xy0(tr.position_xy), *_xy0(tr.velocity_xy), _covariance(tr.covariance),
            _float32(height) if math.isfinite(height) else 0.0, int(tr.state) & 0xFF,
            *_stamp(tr.first_seen_s), *_stamp(tr.last_seen_s), len(cameras), *strings)
        pieces.append(data)
        offset += len(data)
    return b"".join(pieces)
