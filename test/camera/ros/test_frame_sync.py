"""The colour/depth synchroniser pairs by stamp within the slop, never queues stale frames, and checks each
stamp against the receive clock so that no single stamp can silence the camera."""

from __future__ import annotations

import pytest

from face_reid_camera.ros.frame_sync import MAX_STAMP_FUTURE_S, PATTERN_AHEAD_S, StampSynchronizer


def test_pairs_within_slop() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01)
    assert sync.add_color(1.000, "c1", 1.01) is None
    assert sync.add_depth(1.004, "d1", 1.01) == (1.000, "c1", "d1")
    assert sync.stats.pairs == 1


def test_no_pair_outside_slop() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01)
    sync.add_color(1.000, "c1", 1.1)
    assert sync.add_depth(1.050, "d1", 1.1) is None


def test_newest_pair_wins_and_older_frames_are_dropped() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.005, buffer_size=4)
    for i in range(3):
        sync.add_color(1.0 + i * 0.033, f"c{i}", 1.1)
    # depth of the newest colour frame arrives: the two older colour frames are stale
    assert sync.add_depth(1.066, "d2", 1.1) == (1.066, "c2", "d2")
    assert sync.stats.dropped_color == 2
    # a late depth frame for an already superseded colour frame is rejected, not paired
    assert sync.add_depth(1.033, "d1", 1.1) is None
    assert sync.stats.rejected["stamp_out_of_order"] == 1


def test_buffer_is_bounded() -> None:
    sync: StampSynchronizer[int, int] = StampSynchronizer(slop_s=0.001, buffer_size=2)
    for i in range(10):
        sync.add_color(float(i), i, 10.0)
    assert sync.stats.dropped_color == 8


def _valid_pairs(sync: StampSynchronizer[str, str], t0: float, n: int) -> list[tuple[float, str, str] | None]:
    """``n`` colour/depth pairs 33 ms apart from ``t0``, each received 10 ms after its stamp."""
    out = []
    for k in range(n):
        t = t0 + k * 0.033
        sync.add_color(t, f"c{k}", t + 0.01)
        out.append(sync.add_depth(t, f"d{k}", t + 0.01))
    return out


def test_a_future_stamp_is_dropped_and_the_valid_pairs_after_it_pair() -> None:
    """The attack: one pair stamped +1 h made the pairing's last stamp +1 h and every later pair out of order."""
    drops: list[tuple[str, str]] = []
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, on_drop=lambda r, t: drops.append((r, t)))
    assert sync.add_color(100.0 + 3600.0, "evil_c", 100.0) is None
    assert sync.add_depth(100.0 + 3600.0, "evil_d", 100.0) is None
    pairs = _valid_pairs(sync, 100.1, 5)
    assert [p[1] if p else None for p in pairs] == ["c0", "c1", "c2", "c3", "c4"]
    assert sync.stats.rejected == {"stamp_future": 2, "stamp_past": 0, "stamp_out_of_order": 0,
                                   "stamp_out_of_pattern": 0}
    assert [r for r, _ in drops] == ["stamp_future", "stamp_future"]
    assert "3600.000 s ahead" in drops[0][1] and drops[0][1].startswith("colour stamp")


def test_future_limit_is_two_seconds_ahead_of_the_receive_clock() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01)
    sync.add_color(10.0 + MAX_STAMP_FUTURE_S + 0.1, "far", 10.0)
    sync.add_color(10.0 + MAX_STAMP_FUTURE_S - 0.1, "near", 10.0)  # a driver clock slightly ahead still works
    assert sync.add_depth(10.0 + MAX_STAMP_FUTURE_S - 0.1, "d", 10.0) == (11.9, "near", "d")
    assert sync.stats.rejected["stamp_future"] == 1


def test_stamps_older_than_max_age_are_dropped_and_zero_means_never() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=0.5)
    assert sync.add_color(9.4, "old", 10.0) is None
    assert sync.add_depth(9.4, "old", 10.0) is None
    assert sync.stats.rejected["stamp_past"] == 2 and sync.stats.pairs == 0
    sync.add_color(9.6, "c", 10.0)
    assert sync.add_depth(9.6, "d", 10.0) == (9.6, "c", "d")
    never: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=0.0)
    never.add_color(1.0, "c", 10_000.0)
    assert never.add_depth(1.0, "d", 10_000.0) == (1.0, "c", "d")
    with pytest.raises(ValueError):
        StampSynchronizer(max_age_s=-1.0)


def test_a_big_step_back_restarts_the_pairing_and_a_small_one_is_out_of_order() -> None:
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01)
    assert all(_valid_pairs(sync, 100.0, 3))
    sync.add_color(100.2, "unpaired", 100.21)  # buffered, never paired: forgotten by the reset below
    # a small step back (0.5 s <= RESET_BACKWARD_S): dropped, counted, no reset
    assert sync.add_color(99.6, "late", 100.3) is None
    assert sync.stats.rejected["stamp_out_of_order"] == 1 and sync.stats.resets == 0
    # a bag loop / clock jump: both streams go back 50 s (the receive clock too) and pairing carries on
    pairs = _valid_pairs(sync, 50.0, 3)
    assert [p[1] if p else None for p in pairs] == ["c0", "c1", "c2"]
    assert sync.stats.resets == 1  # the depth stream's jump follows the colour's reset: not a second one
    # the colour frame buffered before the jump was forgotten: a depth frame of its stamp pairs with nothing
    assert sync.add_depth(100.2, "d", 100.21) is None
    assert sync.stats.pairs == 6 and sync.stats.rejected["stamp_future"] == 0


def _stream_with_injections(sync: StampSynchronizer[str, str], inject, seconds: float = 10.0) -> int:
    """30 Hz colour/depth pairs (received 10 ms after their stamp, depth 5 ms after colour); ``inject(sync, now)``
    called at each frame. Returns the regular pairs that went out."""
    pairs, next_injection = 0, 0.5
    for k in range(int(seconds * 30)):
        t = 1000.0 + k / 30
        sync.add_color(t, f"c{k}", t + 0.010)
        if t - 1000.0 >= next_injection:
            inject(sync, t + 0.012)
            next_injection += 0.9
        pair = sync.add_depth(t, f"d{k}", t + 0.015)
        pairs += pair is not None and pair[1] == f"c{k}"
    return pairs


def test_a_depth_image_stamped_095_s_ahead_every_09_s_is_dropped_and_the_regular_pairs_go_out() -> None:
    """Break 6: one extra depth image stamped +0.95 s every 0.9 s made every regular depth image "out of order"
    (0 frames out). It is out of the stream's pattern: dropped, counted, the pairing untouched."""
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=0.5)
    pairs = _stream_with_injections(sync, lambda s, now: s.add_depth(now + 0.95, "evil", now))
    assert pairs == 300, f"{pairs} of 300 regular pairs out"
    assert sync.stats.rejected["stamp_out_of_pattern"] == 11 and sync.stats.resets == 0
    assert sync.stats.rejected["stamp_out_of_order"] == 0


def test_an_image_a_little_ahead_costs_at_most_its_own_pair_and_one_far_behind_resets_nothing() -> None:
    """Within the pattern's tolerance an early image is buffered in stamp order: the regular images keep pairing
    (before, it became its stream's last stamp and the regular ones after it were refused until it passed)."""
    ahead = PATTERN_AHEAD_S * 0.8
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=5.0)
    pairs = _stream_with_injections(sync, lambda s, now: s.add_depth(now + ahead, "early", now))
    assert pairs >= 300 - 11, f"{pairs} of 300 regular pairs out"
    behind: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=5.0)
    pairs = _stream_with_injections(behind, lambda s, now: s.add_color(now - 1.5, "old", now))
    assert pairs == 300 and behind.stats.resets == 0  # before: each reset the pairing
    assert behind.stats.rejected["stamp_out_of_pattern"] == 11


def test_forged_pairs_a_little_ahead_wait_until_due_and_cost_the_regular_pairs_little() -> None:
    """A colour+depth pair stamped +0.2 s (within the pattern's tolerance) five times a second: it pairs only
    when the receive clock makes it due, so the regular pairs before it still go out (before: it paired at once,
    the regular images up to its stamp were out of order: 15 of 300 out)."""
    def forged_pair(s: StampSynchronizer[str, str], now: float) -> None:
        s.add_color(now + 0.2, "evil_c", now)
        s.add_depth(now + 0.2, "evil_d", now)

    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=0.5)
    pairs = 0
    for k in range(300):
        t = 1000.0 + k / 30
        sync.add_color(t, f"c{k}", t + 0.010)
        if k % 6 == 5:
            forged_pair(sync, t + 0.012)
        pair = sync.add_depth(t, f"d{k}", t + 0.015)
        pairs += pair is not None and pair[1] == f"c{k}"
    assert pairs >= 200, f"{pairs} of 300 regular pairs out"


def test_a_lasting_step_of_the_stamps_is_followed_within_the_pattern_window() -> None:
    """The driver's clock steps 1.5 s ahead for good (within the future limit): out of pattern for about half
    the window, then it is the pattern and every pair goes out."""
    sync: StampSynchronizer[str, str] = StampSynchronizer(slop_s=0.01, max_age_s=0.5)
    assert _stream_with_injections(sync, lambda s, now: None, 2.0) == 60
    out = []
    for k in range(30):
        t = 1100.0 + k / 30
        sync.add_color(t + 1.5, f"c{k}", t)
        out.append(sync.add_depth(t + 1.5, f"d{k}", t + 0.005))
    assert sum(p is not None for p in out) >= 20 and all(out[-10:])


def test_invalid_arguments() -> None:
    with pytest.raises(ValueError):
        StampSynchronizer(slop_s=-1)
    with pytest.raises(ValueError):
        StampSynchronizer(buffer_size=0)
