"""The colour/depth synchroniser pairs by stamp within the slop and never queues stale frames."""

from __future__ import annotations

import pytest

from face_reid_camera.ros.frame_sync import StampSynchronizer


def test_pairs_within_slop() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01)
    assert sync.add_color(1.000, "c1") is None
    assert sync.add_depth(1.004, "d1") == (1.000, "c1", "d1")
    assert sync.stats.pairs == 1


def test_no_pair_outside_slop() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01)
    sync.add_color(1.000, "c1")
    assert sync.add_depth(1.050, "d1") is None


def test_newest_pair_wins_and_older_frames_are_dropped() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.005, buffer_size=4)
    for i in range(3):
        sync.add_color(1.0 + i * 0.033, f"c{i}")
    # depth of the newest colour frame arrives: the two older colour frames are stale
    assert sync.add_depth(1.066, "d2") == (1.066, "c2", "d2")
    assert sync.stats.dropped_color == 2
    # a late depth frame for an already superseded colour frame is rejected, not paired
    assert sync.add_depth(1.033, "d1") is None
    assert sync.stats.rejected_out_of_order == 1


def test_buffer_is_bounded() -> None:
    sync: StampSynchronizer[int, int] = StampSynchronizer(slop_s=0.001, buffer_size=2)
    for i in range(10):
        sync.add_color(float(i), i)
    assert sync.stats.dropped_color == 8


def test_invalid_arguments() -> None:
    with pytest.raises(ValueError):
        StampSynchronizer(slop_s=-1)
    with pytest.raises(ValueError):
        StampSynchronizer(buffer_size=0)
