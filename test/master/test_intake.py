"""FrameIntake / CycleBudget: stamp order, fair oldest-first dropping, the budget learnt from cycle costs."""

from __future__ import annotations

import math

import pytest

from face_reid_master.intake import CycleBudget, FrameIntake, PendingFrame


def _intake(frames: list[tuple[str, float]]) -> FrameIntake[int]:
    intake: FrameIntake[int] = FrameIntake()
    for k, (camera, stamp) in enumerate(frames):
        intake.add(PendingFrame(camera, stamp, k))
    return intake


def test_take_returns_everything_in_stamp_order_and_empties_the_intake() -> None:
    intake = _intake([("a", 3.0), ("b", 1.0), ("a", 2.0), ("b", math.nan), ("c", 1.5)])
    frames, dropped = intake.take(100)
    assert dropped == 0 and len(intake) == 0
    assert [f.payload for f in frames] == [1, 4, 2, 0, 3]  # the NaN stamp last: the core refuses it
    assert intake.take(100) == ([], 0)
    intake.add(PendingFrame("a", 5.0, 9))
    intake.clear()  # e.g. deactivating: gone, but not counted as dropped for overload
    assert len(intake) == 0 and intake.dropped == 0


def test_over_the_limit_the_fullest_camera_loses_its_oldest_first() -> None:
    frames = [("a", 10.0 + k) for k in range(6)] + [("b", 12.5), ("c", 0.5)]
    intake = _intake(frames)
    kept, dropped = intake.take(4)
    assert dropped == 4 and intake.dropped == 4
    assert [(f.camera_id, f.stamp_s) for f in kept] == [("c", 0.5), ("b", 12.5), ("a", 14.0), ("a", 15.0)]
    # a camera running an hour behind is not starved either: it keeps its newest frame
    intake = _intake([("late", 1.0), ("late", 2.0)] + [(f"cam{k}", 3600.0 + k) for k in range(3)])
    kept, _ = intake.take(4)
    assert ("late", 2.0) in [(f.camera_id, f.stamp_s) for f in kept] and intake.dropped == 1


def test_take_refuses_a_limit_below_one() -> None:
    with pytest.raises(ValueError, match="max_frames"):
        FrameIntake().take(0)


def test_budget_is_unlimited_until_measured_then_budget_over_mean_cost() -> None:
    budget = CycleBudget(budget_ms=40.0, min_frames=4, smoothing=0.5)
    assert budget.frames() >= 1_000_000
    budget.spent(10, 10.0)  # 1 ms per frame
    assert budget.frames() == 40
    budget.spent(10, 30.0)  # 3 ms: the mean moves half way (2 ms)
    assert budget.mean_cost_ms == pytest.approx(2.0) and budget.frames() == 20
    budget.spent(1, 1000.0)  # a very slow frame: still min_frames per cycle
    assert budget.frames() == 4
    budget.spent(0, 5.0)  # an empty cycle teaches nothing
    budget.spent(3, math.nan)
    assert budget.mean_cost_ms == pytest.approx(0.5 * 2.0 + 0.5 * 1000.0)


def test_the_cost_paid_once_per_cycle_is_learnt_apart_from_the_cost_per_frame() -> None:
    budget = CycleBudget(budget_ms=25.0, min_frames=1, smoothing=1.0)
    budget.spent(2, 7.0, cycle_ms=5.0)  # 1 ms per frame + 5 ms identity update
    assert budget.mean_cost_ms == pytest.approx(1.0) and budget.mean_cycle_ms == pytest.approx(5.0)
    assert budget.frames() == 20  # (25 - 5) / 1, where 25 / 3.5 per frame of this cycle would allow 7
    budget.spent(4, 3.0, cycle_ms=9.0)  # the part paid once cannot exceed the whole
    assert budget.mean_cost_ms == pytest.approx(0.0) and budget.mean_cycle_ms == pytest.approx(3.0)
    assert budget.frames() == 22_000  # a frame is taken to cost at least 1 us, not nothing


@pytest.mark.parametrize(("kwargs", "name"), [({"budget_ms": 0.0}, "budget_ms"), ({"budget_ms": math.inf}, "budget_ms"),
                                              ({"min_frames": 0}, "min_frames"), ({"smoothing": 0.0}, "smoothing"),
                                              ({"smoothing": 1.5}, "smoothing")])
def test_budget_arguments_are_checked_by_name(kwargs: dict[str, float], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        CycleBudget(**kwargs)
