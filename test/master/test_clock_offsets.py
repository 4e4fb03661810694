"""ClockOffsets: per-camera median of receive - stamp - processing; warnings beyond a limit; bounded memory."""

from __future__ import annotations

import math

import pytest

from face_reid_master.clock_offsets import ClockOffsets


def test_offsets_are_per_camera_medians_with_processing_deducted() -> None:
    clocks = ClockOffsets(window=5)
    for k in range(10):
        clocks.observe("synced", 100.0 + k, 100.0 + k + 0.03 + 0.08, processing_s=0.08)  # 30 ms transport
        clocks.observe("behind", 100.0 + k, 100.0 + k + 0.75)  # its clock 0.75 s behind ours
        clocks.observe("ahead", 100.0 + k, 100.0 + k - 0.4)
    clocks.observe("behind", 0.0, 1e9)  # one wild frame does not move a median of five
    assert clocks.offset_s("synced") == pytest.approx(0.03)
    assert clocks.offset_s("behind") == pytest.approx(0.75)
    assert math.isnan(clocks.offset_s("never"))
    assert list(clocks.beyond(0.2)) == ["behind", "ahead"]  # largest first, both directions
    assert clocks.beyond(0.2)["ahead"] == pytest.approx(-0.4)


def test_bad_values_are_ignored_and_memory_is_bounded() -> None:
    clocks = ClockOffsets(max_cameras=3)
    clocks.observe("a", math.nan, 1.0)
    clocks.observe("a", 1.0, math.inf)
    assert math.isnan(clocks.offset_s("a"))
    clocks.observe("a", 1.0, 1.5, processing_s=math.nan)  # a nonsense processing time counts as 0
    assert clocks.offset_s("a") == pytest.approx(0.5)
    for k in range(100):
        clocks.observe(f"hostile_{k}" + "x" * 10_000, 1.0, 1.0)
    assert len(clocks._seen) == 3 and all(len(c) <= 256 for c in clocks._seen)
    with pytest.raises(ValueError, match="window"):
        ClockOffsets(window=0)
