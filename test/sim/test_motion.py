"""Tests of the simulator's motion: trajectories, the random planner, and the loss rate its defaults give."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.sim.motion import MotionConfig, Planner, Trajectory, plan_trajectory, sample_trajectories
from face_reid_master.sim.visibility import camera_visibility, count_losses
from face_reid_master.sim.world import make_world


def test_motion_stays_in_the_room_except_through_doors() -> None:
    world = make_world(3, np.random.default_rng(1))
    cfg = MotionConfig()
    t = np.arange(0.0, 300.0, 0.05)
    outside_seen = 0
    for seed in range(8):
        traj = plan_trajectory(world, np.random.default_rng(seed), 300.0, cfg)
        assert traj.t_s[-1] >= 300.0
        xy, facing = traj.sample(t)
        assert world.allowed(xy).all(), "a person left the room other than through a door"
        outside = ~world.room.contains(xy)
        outside_seen += int(outside.sum())
        for k in np.flatnonzero(outside):
            assert any(d.in_corridor(xy[k]) for d in world.doors)
        # speed never above the maximum walking speed
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1) / 0.05
        assert step.max() <= cfg.speed_range_mps[1] + 1e-6
        # while walking, people face where they go
        moving = step > 0.3
        heading = np.arctan2(*np.diff(xy, axis=0)[moving][:, ::-1].T)
        diff = np.angle(np.exp(1j * (heading - facing[1:][moving])))
        assert np.mean(np.abs(diff) < 0.2) > 0.95
        assert 1.55 <= traj.height_m <= 1.90
    assert outside_seen > 0, "nobody ever went out: exits are not simulated"


def test_trajectory_validation_and_sampling() -> None:
    traj = Trajectory(np.array([0.0, 2.0]), np.array([[0.0, 0.0], [2.0, 0.0]]), np.array([0.0, 0.0]), 1.7)
    xy, _ = traj.sample(np.array([-1.0, 1.0, 5.0]))
    np.testing.assert_allclose(xy, [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    with pytest.raises(ValueError, match="strictly increasing"):
        Trajectory(np.array([0.0, 0.0]), np.zeros((2, 2)), np.zeros(2), 1.7)
    with pytest.raises(ValueError, match="finite"):
        Trajectory(np.array([0.0, 1.0]), np.array([[0.0, np.nan], [0.0, 0.0]]), np.zeros(2), 1.7)
    with pytest.raises(ValueError, match="height_m"):
        Trajectory(np.array([0.0, 1.0]), np.zeros((2, 2)), np.zeros(2), 3.0)
    with pytest.raises(ValueError, match="exit_probability"):
        MotionConfig(exit_probability=1.5)
    with pytest.raises(ValueError, match="speed_range_mps"):
        MotionConfig(speed_range_mps=(1.4, 0.6))
    world = make_world(1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="duration_s"):
        plan_trajectory(world, np.random.default_rng(0), float("nan"))


def test_default_scenario_has_about_fifty_losses_in_200_s() -> None:
    # the tuning target: 6 people, 3 cameras, 200 s -> ~50 track losses (the paper: 49 and 58)
    totals = []
    for seed in range(4):
        world = make_world(3, np.random.default_rng([seed, 0]))
        trajs = [plan_trajectory(world, np.random.default_rng([seed, 1, p]), 200.0) for p in range(6)]
        t = np.arange(0.0, 200.0, 0.1)
        xy, facing = sample_trajectories(trajs, t)
        heights = np.array([tr.height_m for tr in trajs])
        in_room = world.room.contains(xy)
        seen = np.zeros(in_room.shape, dtype=bool)
        for cam in world.cameras:
            seen |= camera_visibility(cam, xy, facing, heights, in_room).detectable
        totals.append(count_losses(t, seen.T).total_losses)
    assert 35 <= np.mean(totals) <= 70, totals



def test_planner_branches_merge_zero_length_steps_and_commit() -> None:
    world = make_world(1, np.random.default_rng(0))
    plan = Planner(world, np.random.default_rng(0), MotionConfig(turn_rate_rad_s=2.0), 0.0, np.zeros(2), 0.0)
    plan.walk_to(np.array([0.0, 2.0]), 1.0)  # turn pi/2 at 2 rad/s, then 2 m at 1 m/s
    assert plan.t == pytest.approx([0.0, np.pi / 4, np.pi / 4 + 2.0])
    move = plan.branch()
    move.hold(0.0)  # zero length: no knot
    move.turn_to(np.pi / 2 + 1e-7)  # below the time resolution: updates the last knot
    move.hold(1.0)
    assert len(plan.t) == 3, "a branch leaves its planner alone until committed"
    plan.commit(move)
    traj = plan.trajectory(1.7)
    assert traj.t_s.tolist() == pytest.approx([0.0, np.pi / 4, np.pi / 4 + 2.0, np.pi / 4 + 3.0])
    assert traj.facing_rad[-2:] == pytest.approx([np.pi / 2 + 1e-7] * 2, abs=1e-12)
    np.testing.assert_allclose(traj.xy[-1], [0.0, 2.0])
