"""Late frames within the bound (tracking.history): the track states equal stamp-order processing."""

from __future__ import annotations

import itertools
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from tracking_test_helpers import assert_one_track_per_person, det, run, snap, straight_frames
from trajectories import (
    CameraFov,
    Scenario,
    random_walkers,
)

from face_reid_master.tracking.records import Detection, FrameStatus
from face_reid_master.tracking.tracker import Tracker


def test_late_frame_within_bound_gives_exactly_the_in_order_state() -> None:
    frames = straight_frames([0.0, 0.1, 0.2, 0.3, 0.4])
    ordered, shuffled = Tracker(), Tracker()
    for t, c, d in frames:
        ordered.update(d, t, c)
    statuses = [shuffled.update(frames[k][2], frames[k][0], frames[k][1]).status for k in (0, 1, 3, 4, 2)]
    assert statuses[-1] is FrameStatus.APPLIED_LATE and statuses[:-1] == [FrameStatus.APPLIED] * 4
    a, b = snap(ordered, 1), snap(shuffled, 1)
    np.testing.assert_allclose(b.position_xy, a.position_xy, atol=1e-12)
    np.testing.assert_allclose(b.velocity_xy, a.velocity_xy, atol=1e-12)
    np.testing.assert_allclose(b.covariance, a.covariance, atol=1e-12)
    assert b.hits == a.hits == 5 and b.last_seen_s == 0.4 and shuffled.stats.frames_out_of_order == 1


def test_late_detection_older_than_the_track_joins_it() -> None:
    # Camera b's frame (t = 0.10) arrives before camera a's (t = 0.05) of the same person.
    tracker = Tracker()
    assert tracker.update([det(1.0, 1.0)], 0.10, "b").created == (1,)
    res = tracker.update([det(0.95, 1.0)], 0.05, "a")
    assert res.status is FrameStatus.APPLIED_LATE and res.associations == ((1, 0),) and res.created == ()
    s = snap(tracker, 1)
    assert s.created_s == 0.05 and s.last_seen_s == 0.10 and s.hits == 2 and s.cameras == {"a", "b"}
    assert s.velocity_xy[0] > 0.0  # re-filtered in stamp order: 0.95 then 1.0 -> moving +x


def test_multi_camera_out_of_order_stream_equals_stamp_order_processing() -> None:
    cams = (
        CameraFov("a", (-3.0, -5.0), math.radians(70), phase_s=0.0),
        CameraFov("b", (3.0, -5.0), math.radians(110), phase_s=0.011, bias_xy=(0.05, -0.03)),
        CameraFov("c", (0.0, 5.0), math.radians(-90), rate_hz=15.0, phase_s=0.02),
    )
    sc = Scenario(
        random_walkers(3, 1, area_m=6.0), cams, 6.0, 0.05, 0.1, latency_s=0.02, latency_jitter_s=0.15, seed=3
    )
    arrival = sc.frames()
    by_stamp = sorted(arrival, key=lambda f: f.stamp_s)
    assert any(b.stamp_s < a.stamp_s for a, b in itertools.pairwise(arrival))
    t1, r1 = run(arrival)
    t2, _ = run(by_stamp)
    assert t1.stats.frames_out_of_order > 100 and t1.stats.frames_rejected_late == 0
    s1, s2 = t1.snapshots(at_s=6.0), t2.snapshots(at_s=6.0)
    assert [s.track_id for s in s1] == [s.track_id for s in s2] and len(s1) == 3
    for a, b in zip(s1, s2, strict=True):
        np.testing.assert_allclose(a.position_xy, b.position_xy, atol=1e-9)
        np.testing.assert_allclose(a.covariance, b.covariance, atol=1e-9)
        assert a.hits == b.hits
    assert_one_track_per_person(arrival, r1)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(delays=st.lists(st.floats(0.0, 0.25), min_size=30, max_size=30), seed=st.integers(0, 1000))
def test_any_arrival_order_within_the_bound_gives_the_stamp_order_states(
    delays: list[float], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    frames = []
    for k in range(30):  # three cameras interleaved at ~90 Hz overall, two people 4 m apart
        t, cam = k / 90, "abc"[k % 3]
        people = [
            np.array([0.0, 0.0]) + t * np.array([1.0, 0.3]),
            np.array([4.0, 0.0]) + t * np.array([-0.5, 0.8]),
        ]
        dets = [
            Detection(p + rng.normal(scale=0.03, size=2), 0.05) for p in people if rng.random() > 0.2
        ]
        frames.append((t, cam, dets))
    arrival = [frames[k] for k in sorted(range(30), key=lambda k: frames[k][0] + delays[k])]
    ordered, shuffled = Tracker(), Tracker()
    for t, cam, dets in frames:
        ordered.update(dets, t, cam)
    results = [shuffled.update(dets, t, cam) for t, cam, dets in arrival]
    assert all(r.accepted for r in results)
    a = sorted(ordered.snapshots(at_s=0.5), key=lambda s: s.position_xy[0])
    b = sorted(shuffled.snapshots(at_s=0.5), key=lambda s: s.position_xy[0])
    assert len(a) == len(b) == 2
    for sa, sb in zip(a, b, strict=True):
        np.testing.assert_allclose(sb.position_xy, sa.position_xy, atol=1e-9)
        np.testing.assert_allclose(sb.covariance, sa.covariance, atol=1e-9)
        assert (sb.hits, sb.state, sb.created_s, sb.last_seen_s) == (
            sa.hits,
            sa.state,
            sa.created_s,
            sa.last_seen_s,
        )
