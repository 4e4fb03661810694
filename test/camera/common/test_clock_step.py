"""ClockStepDetector: a wall clock step (either way) is seen against the monotonic clock, lasts until corrected
or settled, and its effect is counted; slewing is not a step."""

from __future__ import annotations

import pytest

from face_reid_camera.common.clock_step import ClockStepDetector

WALL0 = 1.7e9


def _run(det: ClockStepDetector, seconds: range, offset_at) -> list[bool]:
    """One reading a second; ``offset_at(t)`` the wall clock's error at monotonic second t. Stepped per reading."""
    out = []
    for t in seconds:
        det.update(WALL0 + t + offset_at(t), float(t))
        out.append(det.stepped)
    return out


def test_a_glitch_of_120_s_for_5_s_is_an_error_while_it_lasts_and_two_steps() -> None:
    det = ClockStepDetector()
    stepped = _run(det, range(0, 30), lambda t: 120.0 if 10 <= t < 15 else 0.0)
    assert stepped == [False] * 10 + [True] * 5 + [False] * 15
    assert det.steps == 2 and det.last_step_s == pytest.approx(-120.0)


def test_a_backward_step_is_seen_and_a_step_that_holds_is_taken_as_the_clock_after_settle_s() -> None:
    det = ClockStepDetector(settle_s=20.0)
    _run(det, range(0, 10), lambda t: 0.0)
    det.update(WALL0 + 10 - 60.0, 10.0)
    assert det.stepped and det.offset_s == pytest.approx(-60.0) and "-60.0 s" in det.describe()
    stepped = _run(det, range(11, 40), lambda t: -60.0)
    assert stepped[:19] == [True] * 19 and not any(stepped[19:]) and det.steps == 1


def test_slewing_is_followed_not_a_step_and_refusals_during_a_step_are_counted() -> None:
    det = ClockStepDetector()
    assert not any(_run(det, range(0, 600), lambda t: t * 5e-4))  # 500 ppm for 10 min: 0.3 s in all
    assert det.steps == 0
    det.count_refused(7)
    det.update(WALL0 + 600 + 120.0, 600.0)
    det.count_refused(37)  # 30 refused while stepped
    det.update(WALL0 + 601, 601.0)
    det.count_refused(40)  # 3 more, up to the correction
    det.update(WALL0 + 602, 602.0)
    det.count_refused(50)  # after it: not the step's
    assert det.refused_during_steps == 33 and det.steps == 2
