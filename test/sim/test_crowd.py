"""Tests of people keeping out of each other's way (face_reid_master.sim.crowd): planned paths that go through each
other become passes at the passing distance, people still cross, and a crowded scenario never has two people in the
room closer than the passing distance."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.sim.crowd import CrowdConfig, closest_approach, keep_apart
from face_reid_master.sim.motion import MotionConfig, Planner, Trajectory, plan_trajectory, sample_trajectories
from face_reid_master.sim.world import Room, World, make_world

TOLERANCE_M = 1e-6  # the distance holds at every instant: only rounding


def _world() -> World:
    world = make_world(2, np.random.default_rng(0), room=Room(10.0, 8.0))
    return World(world.room, world.cameras, world.doors)


def _walk(world: World, start: tuple[float, float], *legs: tuple[float, float] | float, speed: float = 1.0
          ) -> Trajectory:
    """A scripted person: from ``start``, walking to points (x, y) and holding (a float: seconds)."""
    plan = Planner(world, np.random.default_rng(0), MotionConfig(turn_rate_rad_s=100.0), 0.0, np.array(start), 0.0)
    for leg in legs:
        if isinstance(leg, float):
            plan.hold(leg)
        else:
            plan.walk_to(np.array(leg), speed)
    plan.hold(60.0)
    return plan.trajectory(1.7)


def _closest(world: World, trajectories: list[Trajectory], duration_s: float) -> float:
    t = np.arange(0.0, duration_s, 0.01)
    xy, _ = sample_trajectories(trajectories, t)
    return closest_approach(xy, world.room.contains(xy))


def test_head_on_walkers_pass_each_other_instead_of_walking_through() -> None:
    world = _world()
    plans = [_walk(world, (-3.0, 0.0), (3.0, 0.0)), _walk(world, (3.0, 0.0), (-3.0, 0.0))]
    assert _closest(world, plans, 20.0) < 0.05, "the planned paths go through each other"
    people, stats = keep_apart(world, plans, 0.0, 20.0)
    assert _closest(world, people, 20.0) >= 0.5 - TOLERANCE_M
    # they still get where they were going (past each other: a real crossing), a little late at most
    final = np.array([tr.sample(np.array([20.0]))[0][0] for tr in people])
    np.testing.assert_allclose(final, [[3.0, 0.0], [-3.0, 0.0]], atol=0.05)
    assert stats.max_delay_s < 3.0 and stats.stood_steps == 0
    # by sidestepping: somebody left the straight line on the way
    mid = np.array([tr.sample(np.array([3.0]))[0][0] for tr in people])
    assert np.abs(mid[:, 1]).max() > 0.1


def test_crossing_paths_still_cross_at_the_passing_distance() -> None:
    world = _world()
    # both reach the origin at t = 3 s
    plans = [_walk(world, (-3.0, 0.0), (3.0, 0.0)), _walk(world, (0.0, -3.0), (0.0, 3.0))]
    assert _closest(world, plans, 12.0) < 0.05
    people, _ = keep_apart(world, plans, 0.0, 12.0, CrowdConfig(passing_distance_m=0.7))
    assert _closest(world, people, 12.0) >= 0.7 - TOLERANCE_M
    t = np.arange(0.0, 12.0, 0.05)
    a, _ = people[0].sample(t)
    b, _ = people[1].sample(t)
    # each crossed the other's line: the paths still cross
    assert a[0, 0] < -2.9 and a[-1, 0] > 2.9 and b[0, 1] < -2.9 and b[-1, 1] > 2.9


def test_a_walker_goes_round_somebody_standing_in_the_way() -> None:
    world = _world()
    plans = [_walk(world, (0.0, 0.0), 30.0), _walk(world, (-3.0, 0.0), (3.0, 0.0), speed=1.2)]
    people, _ = keep_apart(world, plans, 0.0, 15.0, CrowdConfig(passing_distance_m=0.6))
    assert _closest(world, people, 15.0) >= 0.6 - TOLERANCE_M
    end = people[1].sample(np.array([15.0]))[0][0]
    np.testing.assert_allclose(end, [3.0, 0.0], atol=0.05)


def test_people_who_never_meet_keep_their_plans() -> None:
    world = _world()
    plans = [_walk(world, (-3.0, 2.0), (3.0, 2.0)), _walk(world, (-3.0, -2.0), (3.0, -2.0))]
    people, stats = keep_apart(world, plans, 0.0, 10.0)
    t = np.arange(0.0, 10.0, 0.05)
    for plan, person in zip(plans, people, strict=True):
        np.testing.assert_allclose(person.sample(t)[0], plan.sample(t)[0], atol=1e-9)
        np.testing.assert_allclose(person.sample(t)[1], plan.sample(t)[1], atol=1e-9)
    assert stats.slowed_share == 0.0 and stats.aside_share == 0.0 and stats.max_delay_s == 0.0


@pytest.mark.parametrize("passing_m", [0.4, 0.5, 0.8])
def test_a_crowded_room_never_has_two_people_closer_than_the_passing_distance(passing_m: float) -> None:
    # 8 people planned alone in a 6 x 5 m room with 2 doors for 60 s: their plans walk through each other
    world = make_world(2, np.random.default_rng(3), room=Room(6.0, 5.0))
    plans = [plan_trajectory(world, np.random.default_rng([3, p]), 60.0) for p in range(8)]
    assert _closest(world, plans, 60.0) < 0.1
    people, stats = keep_apart(world, plans, 0.0, 60.0, CrowdConfig(passing_distance_m=passing_m))
    assert _closest(world, people, 60.0) >= passing_m - TOLERANCE_M
    assert stats.closest_m >= passing_m - TOLERANCE_M and stats.stood_steps == 0
    assert 0.0 < stats.slowed_share < 0.5 and stats.max_delay_s < 40.0
    t = np.arange(0.0, 60.0, 0.05)
    for person, plan in zip(people, plans, strict=True):
        xy, _ = person.sample(t)
        assert world.allowed(xy).all(), "somebody left the room other than through a door"
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1) / 0.05
        assert step.max() < 2.5  # walking pace plus a sidestep
        assert person.height_m == plan.height_m
    # deterministic
    again, _ = keep_apart(world, plans, 0.0, 60.0, CrowdConfig(passing_distance_m=passing_m))
    for a, b in zip(people, again, strict=True):
        assert np.array_equal(a.t_s, b.t_s) and np.array_equal(a.xy, b.xy) and np.array_equal(a.facing_rad,
                                                                                              b.facing_rad)


def test_passing_distance_validation() -> None:
    assert MotionConfig().passing_distance_m == 0.5
    MotionConfig(passing_distance_m=0.0)  # people walk through each other, as before
    for bad in (0.3, 0.9, -0.5, float("nan")):
        with pytest.raises(ValueError, match="passing_distance_m"):
            MotionConfig(passing_distance_m=bad)
        with pytest.raises(ValueError, match="passing_distance_m"):
            CrowdConfig(passing_distance_m=bad)
    with pytest.raises(ValueError, match="step_s"):
        CrowdConfig(step_s=0.0)
    with pytest.raises(ValueError, match="duration_s"):
        keep_apart(_world(), [], 0.0, 0.0)
    assert keep_apart(_world(), [], 0.0, 1.0)[0] == []
