"""Property-based test: random (often malformed) camera frames never break the master core."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.tracking.config import TrackerConfig

_floats = st.one_of(
    st.floats(-20, 20), st.just(math.nan), st.just(math.inf), st.just(-math.inf), st.floats(-1e12, 1e12)
)
_rng = np.random.default_rng(0)
_FACES = _rng.normal(0, 0.05, (4, 128)).astype(np.float32)


@st.composite
def _embedding(draw: st.DrawFn) -> np.ndarray | None:
    kind = draw(st.sampled_from(["none", "face", "face", "short", "long", "nan", "inf", "empty"]))
    if kind == "none":
        return None
    if kind == "face":
        face = draw(st.integers(0, len(_FACES) - 1))
        return _FACES[face] + np.float32(draw(st.floats(-0.02, 0.02)))
    if kind == "short":
        return np.zeros(draw(st.integers(1, 127)), np.float32)
    if kind == "long":
        return np.zeros(draw(st.integers(129, 300)), np.float32)
    if kind == "empty":
        return np.zeros(0, np.float32)
    bad = np.zeros(128, np.float32)
    bad[draw(st.integers(0, 127))] = np.nan if kind == "nan" else np.inf
    return bad


@st.composite
def _person(draw: st.DrawFn) -> PersonRecord:
    size = draw(st.sampled_from([3, 3, 3, 2, 1, 0]))
    pos = np.array([draw(_floats) for _ in range(size)], dtype=np.float64)
    return PersonRecord(
        pos, draw(st.one_of(st.floats(-1, 1), st.just(math.nan))), draw(_floats), draw(_embedding()),
        draw(st.floats(0, 1)), draw(st.floats(-1, 2)),
    )


@st.composite
def _frame(draw: st.DrawFn) -> CameraFrameRecord:
    stamp = draw(st.one_of(st.floats(0, 60), st.just(math.nan), st.just(math.inf), st.floats(-1e9, 1e9)))
    camera = draw(st.sampled_from(["cam_a", "cam_b", "", "unknown_cam"]))
    return CameraFrameRecord(camera, stamp, tuple(draw(st.lists(_person(), max_size=6))))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_frame(), min_size=1, max_size=40), st.booleans())
def test_random_frames_never_break_the_core(frames: list[CameraFrameRecord], with_clock: bool) -> None:
    core = MasterCore(MasterConfig(known_camera_ids=("cam_a", "cam_b"), tracker=TrackerConfig()))
    for frame in frames:
        outcome = core.process_frame(frame, now_s=30.0 if with_clock else None)
        assert isinstance(outcome.accepted, bool)
        if not outcome.accepted:
            assert outcome.reason
        core.tick(frame.stamp_s + 0.1 if math.isfinite(frame.stamp_s) else 0.0)
        tracks = core.tracks()
        for tr in tracks:
            assert np.all(np.isfinite(tr.position_xy)) and np.all(np.isfinite(tr.covariance))
            assert 0.0 <= tr.identity_confidence <= 1.0
        face_ids = [tr.face_id for tr in tracks if tr.face_id]
        assert len(face_ids) == len(set(face_ids)), "one face on two live tracks"
    s = core.stats
    rejected = (
        s.frames_rejected_unknown_camera + s.frames_rejected_stale + s.frames_rejected_future
        + s.frames_rejected_bad_stamp + s.frames_rejected_tracker_late
    )
    assert s.frames_received == len(frames) == s.frames_applied + rejected
