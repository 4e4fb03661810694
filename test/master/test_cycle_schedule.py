"""CycleSchedule: the master node's cycle, identity and publish timing, driven by clocks the test sets."""

from __future__ import annotations

import pytest

from face_reid_master.cycle_schedule import CycleSchedule


def test_a_cycle_waits_out_the_rest_of_the_minimum_period() -> None:
    s = CycleSchedule(min_cycle_period_s=0.05)
    assert s.wait_s(10.0) == 0.0  # no cycle yet
    s.begin_cycle(10.0)
    assert s.wait_s(10.02) == pytest.approx(0.03)
    assert s.wait_s(10.2) == 0.0


def test_the_identity_step_runs_at_most_once_per_period() -> None:
    s = CycleSchedule(identity_period_s=0.5)
    assert s.identity_due(0.0)
    s.identity_ran(0.0)
    assert not s.identity_due(0.3)
    assert s.identity_due(0.5)


def test_the_frame_limit_comes_from_the_measured_cycle_costs() -> None:
    s = CycleSchedule(budget_ms=10.0)
    assert s.begin_cycle(0.0) > 1000  # nothing measured: no limit
    s.cycle_cost(frames=10, elapsed_ms=12.0, once_ms=2.0)  # 1 ms per frame, 2 ms once
    assert s.begin_cycle(1.0) == 8


def test_the_publish_cap_lets_two_through_then_keeps_the_newest_state_for_the_timer() -> None:
    s = CycleSchedule(max_publish_rate_hz=10.0)
    assert s.may_publish(0.0, 1.0) and s.may_publish(0.0, 1.1)  # a burst of 2
    assert not s.may_publish(0.01, 1.2) and not s.may_publish(0.02, 1.3)
    assert s.due_publish(0.05) is None  # half a token back
    assert s.due_publish(0.12) == 1.3  # the newest capped state
    s.published()
    assert s.due_publish(1.0) is None  # nothing left unpublished


def test_no_cap_publishes_every_cycle() -> None:
    s = CycleSchedule()
    assert all(s.may_publish(0.0, float(k)) for k in range(100)) and s.unpublished_stamp is None


@pytest.mark.parametrize("name", ["min_cycle_period_s", "identity_period_s", "max_publish_rate_hz"])
def test_bad_periods_are_named_in_the_error(name: str) -> None:
    with pytest.raises(ValueError, match=name):
        CycleSchedule(**{name: -1.0})
