"""OutputStamps: /tracks_named stamps never ahead of the master's clock, never backwards."""

from __future__ import annotations

import itertools
import math

from face_reid_master.output_stamps import OutputStamps


def test_a_stamp_ahead_of_the_master_clock_is_brought_back_to_it() -> None:
    stamps = OutputStamps()
    assert stamps.next(101.9, 100.0) == 100.0  # a camera's clock 1.9 s ahead
    assert stamps.next(100.05, 100.1) == 100.05  # the tracker's own time when it is behind the clock


def test_stamps_never_step_backwards() -> None:
    stamps = OutputStamps()
    out = [stamps.next(t, now) for t, now in ((10.0, 10.0), (9.8, 10.1), (10.05, 10.2), (9.0, 10.3), (10.3, 10.4))]
    assert out == [10.0, 10.0, 10.05, 10.05, 10.3]


def test_interleaved_cameras_one_ahead_give_stamps_bounded_and_monotonic() -> None:
    """The issue's case: one camera at +1.9 s interleaved with one on time, and the timer's own messages."""
    stamps, out = OutputStamps(), []
    for k in range(100):
        now = 1000.0 + 0.033 * k
        tracker = now + 1.9 if k % 2 else now - 0.01
        if k % 7 == 0:
            tracker = now - 0.3  # a timer message at the tracker's lagged time
        out.append((stamps.next(tracker, now), now))
    assert all(s <= now for s, now in out)
    assert all(b[0] >= a[0] for a, b in itertools.pairwise(out))


def test_no_tracker_time_yet_gives_the_clock_and_a_clock_going_back_wins() -> None:
    stamps = OutputStamps()
    assert stamps.next(-math.inf, 50.0) == 50.0
    assert stamps.next(math.nan, 50.5) == 50.5
    assert stamps.next(50.4, 20.0) == 20.0  # the master's own clock went back: never ahead of it
    stamps.reset()
    assert stamps.next(5.0, 30.0) == 5.0
