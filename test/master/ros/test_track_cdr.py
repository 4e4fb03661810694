"""/tracks_named serialized by the master itself: the same message as rclpy serializes from tracks_to_msg."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.records import NamedTrackRecord
from face_reid_master.ros.convert import tracks_to_msg
from face_reid_master.ros.track_cdr import tracks_to_cdr

rclpy_serialization = pytest.importorskip("rclpy.serialization")
msgs = pytest.importorskip("face_reid_msgs.msg")


def _track(rng: np.random.Generator, tid: int, name: str = "", evidence: str = "",
           cameras: tuple[str, ...] = ("cam00",), height: float = 1.7) -> NamedTrackRecord:
    return NamedTrackRecord(tid, tid % 3, name, float(rng.random()), tid * 7, rng.normal(size=2), rng.normal(size=2),
                            rng.normal(size=(4, 4)), height, tid % 3, 1e9 + float(rng.random()),
                            1.7e9 + float(rng.random()), cameras, evidence)


def _as_sent(data: bytes) -> object:
    return rclpy_serialization.deserialize_message(data, msgs.NamedTrackArray)


@pytest.mark.parametrize("frame_id", ["world", "map", "", "abcdefgh"])
def test_the_bytes_are_the_message_rclpy_would_send(frame_id: str) -> None:
    rng = np.random.default_rng(0)
    cases = [
        [],
        [_track(rng, 1)],
        # strings of every length modulo 4 and 8 shift every later field's alignment; non-ASCII names
        [_track(rng, 1, "Alice", "face", ()), _track(rng, 2, "Bøb ✓", "body", ("a", "bb", "ccc")),
         _track(rng, 3, "x" * 7, "", ("cam1",), height=math.nan)],
        [_track(rng, i, "n" * (i % 5), "both"[: i % 4], tuple(f"c{j}" * j for j in range(i % 4))) for i in range(40)],
    ]
    for tracks in cases:
        reference = rclpy_serialization.serialize_message(tracks_to_msg(tracks, 1.8e9 + 0.123456789, frame_id))
        ours = tracks_to_cdr(tracks, 1.8e9 + 0.123456789, frame_id)
        assert len(ours) == len(reference)
        assert _as_sent(ours) == _as_sent(reference)  # (padding bytes are left undefined by rclpy's serializer)


def test_values_beyond_the_fields_ranges_do_not_crash_the_publisher() -> None:
    rng = np.random.default_rng(1)
    wild = NamedTrackRecord(2**64 + 5, 3, "n", 1e300, 2**40, np.array([1.0, 2.0]), np.zeros(2), np.eye(4), 1e39, 1,
                            -5.0, 3e9, ("c",), "face")
    sent = _as_sent(tracks_to_cdr([wild, _track(rng, 1)], 4e9, "world"))
    first = sent.tracks[0]
    assert first.track_id == 5 and first.face_observations == 2**32 - 1  # wraps as a C cast / saturates
    assert math.isinf(first.identity_confidence) and math.isinf(first.height_m)
    assert first.first_seen.sec == 0 and first.last_seen.sec == 2**31 - 1 and sent.header.stamp.sec == 2**31 - 1
    assert sent.tracks[1].track_id == 1
