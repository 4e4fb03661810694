"""Appearance-aware association: galleries, the appearance gate, people who meet and turn, LOST tracks re-attached."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.tracking.appearance import AppearanceGallery, appearance_distances
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.tracker import Tracker

DIM = 8
LOOK = {0: np.eye(DIM, dtype=np.float32)[0] * 2.0, 1: np.eye(DIM, dtype=np.float32)[1] * 2.0}  # 2.8 apart


def test_a_gallery_keeps_the_newest_and_distances_take_the_nearest() -> None:
    g = AppearanceGallery(2)
    assert g.rows.shape == (0, 0)
    for v in (0.0, 1.0, 3.0):  # the first is pushed out by the third
        g.add(np.full(2, v, np.float32))
    assert sorted(g.rows[:, 0].tolist()) == [1.0, 3.0]
    empty = AppearanceGallery(2)
    det = np.array([[2.9, 2.9], [0.0, 0.0], [np.nan, np.nan]], np.float32)
    d = appearance_distances([g, empty], det)
    assert d[0, 0] == pytest.approx(math.hypot(0.1, 0.1), abs=1e-5)  # nearest: 3.0
    assert d[0, 1] == pytest.approx(math.sqrt(2.0), abs=1e-5)  # nearest: 1.0
    assert np.isnan(d[0, 2]) and np.isnan(d[1]).all()  # unknown detection, empty track
    g.add(np.zeros(3, np.float32))  # another metric (length): the gallery starts afresh
    assert g.rows.shape == (1, 3)


def _walk_past(appearance: bool, seed: int) -> dict[int, set[int]]:
    """Two people walk past each other 0.4 m apart (detections 0.15 m noisy, a fifth missed); track id -> the
    people whose detections it took."""
    rng = np.random.default_rng(seed)
    tracker = Tracker(TrackerConfig())
    took: dict[int, set[int]] = {}
    for k in range(80):
        t = 0.1 * k
        xy = np.array([[0.5 * t, 0.0], [4.0 - 0.5 * t, 0.4]]) + rng.normal(0.0, 0.15, (2, 2))
        seen = np.flatnonzero(rng.random(2) >= 0.2)
        looks = np.stack([LOOK[0], LOOK[1]]) + rng.normal(0.0, 0.1, (2, DIM)).astype(np.float32)
        result = tracker.update_arrays(xy[seen], np.full(seen.size, 0.15), np.full(seen.size, np.nan), t, "cam",
                                       looks[seen] if appearance else None)
        for track_id, det in result.associations:
            took.setdefault(track_id, set()).add(int(seen[det]))
    return took


def test_people_who_walk_past_each_other_keep_their_tracks_by_appearance() -> None:
    swapped = [seed for seed in range(8) if any(len(p) > 1 for p in _walk_past(False, seed).values())]
    assert len(swapped) >= 2, "position alone hardly swapped them: the test would prove little"
    for seed in range(8):
        took = _walk_past(True, seed)
        assert all(len(p) == 1 for p in took.values()), (seed, took)


def test_a_detection_that_looks_like_someone_else_is_gated_out_even_when_closest() -> None:
    tracker = Tracker(TrackerConfig())
    looks = np.stack([LOOK[0]])
    for k in range(5):
        tracker.update_arrays(np.array([[0.1 * k, 0.0]]), np.array([0.05]), np.array([np.nan]), 0.1 * k, "c", looks)
    (track,) = tracker.track_ids()
    stranger = tracker.update_arrays(np.array([[0.5, 0.02]]), np.array([0.05]), np.array([np.nan]), 0.5, "c",
                                     np.stack([LOOK[1]]))
    assert track not in dict(stranger.associations), "another person's appearance joined the track"
    unknown = tracker.update_arrays(np.array([[0.6, 0.0]]), np.array([0.05]), np.array([np.nan]), 0.6, "c",
                                    np.full((1, DIM), np.nan, np.float32))
    assert dict(unknown.associations).get(track) == 0  # no appearance: position decides, as before


@pytest.mark.parametrize("appearance", [True, False])
def test_a_lost_track_takes_back_its_person_beyond_the_position_gate(appearance: bool) -> None:
    config = TrackerConfig(lost_after_s=0.5, delete_after_s=5.0)
    tracker = Tracker(config)
    look = np.stack([LOOK[0]]) if appearance else None
    for k in range(10):  # walks +x at 0.5 m/s, then is hidden for 2 s, having stopped and turned
        tracker.update_arrays(np.array([[0.05 * k, 0.0]]), np.array([0.05]), np.array([np.nan]), 0.1 * k, "c", look)
    (track,) = tracker.track_ids()
    tracker.advance(2.9)  # LOST by now; predicted 1.45 m further along +x
    back = tracker.update_arrays(np.array([[0.2, 0.6]]), np.array([0.05]), np.array([np.nan]), 2.9, "c", look)
    # 1.45 m from the prediction: beyond max_gate_distance_m (1 m); 0.65 m from the last detection (within reach)
    if appearance:
        assert back.track_of_detection() == {0: track} and not back.created
    else:
        assert back.created and back.track_of_detection()[0] != track


def test_a_lost_track_does_not_take_a_detection_that_also_looks_like_another_track() -> None:
    tracker = Tracker(TrackerConfig(lost_after_s=0.5, delete_after_s=5.0))
    twin = np.stack([LOOK[0]])
    for k in range(10):  # the first person, then hidden
        tracker.update_arrays(np.array([[0.05 * k, 0.0]]), np.array([0.05]), np.array([np.nan]), 0.1 * k, "c", twin)
    for k in range(25):  # someone dressed alike walks far off, in view
        tracker.update_arrays(np.array([[3.0, 2.0 + 0.02 * k]]), np.array([0.05]), np.array([np.nan]),
                              1.0 + 0.08 * k, "c", twin)
    lost, other = tracker.track_ids()
    back = tracker.update_arrays(np.array([[0.2, 0.6], [3.0, 2.5]]), np.full(2, 0.05), np.full(2, np.nan), 3.0, "c",
                                 np.stack([LOOK[0], LOOK[0]]))
    assert back.track_of_detection()[1] == other
    assert back.track_of_detection()[0] != lost  # it looks like both tracks: not proof enough


def test_a_look_alike_far_from_every_detection_still_stops_a_lost_track_taking_one() -> None:
    """Only tracks near some detection are associated, but "looks like no other track" counts every track."""
    tracker = Tracker(TrackerConfig(lost_after_s=0.5, delete_after_s=5.0))
    twin = np.stack([LOOK[0]])
    for k in range(10):  # the first person, then hidden
        tracker.update_arrays(np.array([[0.05 * k, 0.0]]), np.array([0.05]), np.array([np.nan]), 0.1 * k, "c", twin)
    for k in range(25):  # someone dressed alike, 8 m off, seen by another camera until just before
        tracker.update_arrays(np.array([[8.0, 2.0 + 0.02 * k]]), np.array([0.05]), np.array([np.nan]),
                              1.0 + 0.08 * k, "d", twin)
    lost, _ = tracker.track_ids()
    back = tracker.update_arrays(np.array([[0.2, 0.6]]), np.array([0.05]), np.array([np.nan]), 3.0, "c", twin)
    assert back.track_of_detection().get(0) != lost
    alone = Tracker(TrackerConfig(lost_after_s=0.5, delete_after_s=5.0))  # without the twin it is taken back
    for k in range(10):
        alone.update_arrays(np.array([[0.05 * k, 0.0]]), np.array([0.05]), np.array([np.nan]), 0.1 * k, "c", twin)
    (track,) = alone.track_ids()
    alone.advance(3.0 - 1e-3)
    assert alone.update_arrays(np.array([[0.2, 0.6]]), np.array([0.05]), np.array([np.nan]), 3.0, "c",
                               twin).track_of_detection() == {0: track}
