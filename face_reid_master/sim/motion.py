"""How simulated people move: piecewise-linear trajectories and the planner that scripts them.

A person's motion is a :class:`Trajectory` (knots of time, floor position, facing), so it can be sampled
exactly at any camera's frame stamps. :func:`plan_trajectory` makes random motion: walking between
waypoints (turning first), pausing to look around, sometimes leaving through a door and coming back;
:class:`Planner` is its knot builder, also used by scripted scenes (the demo). Each person is planned
alone; :func:`face_reid_master.sim.crowd.keep_apart` then plays a day's plans together so that nobody walks
through anybody (``MotionConfig.passing_distance_m``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import is_finite_number
from face_reid_master.sim.visibility import FloatArray
from face_reid_master.sim.world import World, check_min_max, wrap_angle, wrap_angles

__all__ = ["PASSING_DISTANCE_RANGE_M", "MotionConfig", "Planner", "Trajectory", "plan_trajectory",
           "sample_trajectories"]

PASSING_DISTANCE_RANGE_M = (0.4, 0.8)  # centre to centre: shoulders just clear .. a comfortable berth


@dataclass(frozen=True)
class MotionConfig:
    """How people move (seconds, metres, m/s, rad/s); the defaults give the paper's rate of track losses."""

    speed_range_mps: tuple[float, float] = (0.6, 1.4)
    pause_probability: float = 0.5
    pause_range_s: tuple[float, float] = (1.0, 6.0)
    look_hold_range_s: tuple[float, float] = (0.4, 2.0)
    look_around_max_rad: float = 2.1
    turn_rate_rad_s: float = 3.5
    exit_probability: float = 0.12
    outside_range_s: tuple[float, float] = (2.0, 15.0)
    start_inside_probability: float = 0.6
    initial_outside_max_s: float = 15.0
    waypoint_margin_m: float = 1.0
    height_range_m: tuple[float, float] = (1.55, 1.90)
    # people pass each other at least this far apart (centre to centre, m) while both are in the room
    # (face_reid_master.sim.crowd), within PASSING_DISTANCE_RANGE_M; 0 = people walk through each other
    passing_distance_m: float = 0.5

    def __post_init__(self) -> None:
        check_min_max("speed_range_mps", self.speed_range_mps, 0.05, 5.0)
        check_min_max("pause_range_s", self.pause_range_s, 0.0, 600.0)
        check_min_max("look_hold_range_s", self.look_hold_range_s, 0.05, 600.0)
        check_min_max("outside_range_s", self.outside_range_s, 0.0, 3600.0)
        check_min_max("height_range_m", self.height_range_m, 1.0, 2.3)
        for name in ("pause_probability", "exit_probability", "start_inside_probability"):
            value = getattr(self, name)
            if not (is_finite_number(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"MotionConfig.{name} must be a probability in [0, 1], got {value!r}")
        for name in ("turn_rate_rad_s", "look_around_max_rad"):
            value = getattr(self, name)
            if not (is_finite_number(value) and value > 0):
                raise ValueError(f"MotionConfig.{name} must be positive, got {value!r}")
        for name in ("initial_outside_max_s", "waypoint_margin_m"):
            value = getattr(self, name)
            if not (is_finite_number(value) and value >= 0):
                raise ValueError(f"MotionConfig.{name} must be >= 0, got {value!r}")
        low, high = PASSING_DISTANCE_RANGE_M
        value = self.passing_distance_m
        if not (is_finite_number(value) and (value == 0 or low <= value <= high)):
            raise ValueError(f"MotionConfig.passing_distance_m must be 0 (people walk through each other) or within "
                             f"[{low}, {high}] m, got {value!r}")


@dataclass(frozen=True)
class Trajectory:
    """Piecewise-linear motion of one person: knots (time s, floor x/y m, facing rad, unwrapped).

    Between knots position and facing are interpolated linearly; before the first / after the last
    knot they hold. ``height_m`` is the person's standing height.
    """

    t_s: FloatArray
    xy: FloatArray
    facing_rad: FloatArray
    height_m: float

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=np.float64)
        xy = np.asarray(self.xy, dtype=np.float64)
        facing = np.asarray(self.facing_rad, dtype=np.float64)
        if t.ndim != 1 or t.size == 0 or xy.shape != (t.size, 2) or facing.shape != t.shape:
            raise ValueError(
                f"Trajectory needs t (K,), xy (K, 2), facing (K,), got {t.shape} {xy.shape} {facing.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(xy).all() and np.isfinite(facing).all()):
            raise ValueError("Trajectory knots must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("Trajectory knot times must be strictly increasing")
        if not (is_finite_number(self.height_m) and 1.0 <= self.height_m <= 2.3):
            raise ValueError(f"Trajectory.height_m must be in [1.0, 2.3] m, got {self.height_m!r}")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "facing_rad", facing)

    def sample(self, t_s: NDArray[np.floating]) -> tuple[FloatArray, FloatArray]:
        """Positions (n, 2) and facings (n,) wrapped to [-pi, pi) at times ``t_s`` (n,)."""
        t = np.asarray(t_s, dtype=np.float64)
        x = np.interp(t, self.t_s, self.xy[:, 0])
        y = np.interp(t, self.t_s, self.xy[:, 1])
        facing = np.interp(t, self.t_s, self.facing_rad)
        return np.stack([x, y], axis=-1), wrap_angles(facing)


class Planner:
    """Appends the knots of one person's motion: walk (turning first), turn, hold, look around.

    A zero-length step only updates the last knot. :meth:`branch` starts a tentative move where this one
    ends, :meth:`commit` appends it (scripts try moves before keeping them).
    """

    def __init__(self, world: World, rng: np.random.Generator, config: MotionConfig, t0: float,
                 xy: FloatArray, facing: float) -> None:
        self.world, self.rng, self.cfg = world, rng, config
        self.t = [t0]
        self.xy = [np.asarray(xy, dtype=np.float64)]
        self.facing = [float(facing)]

    @property
    def now(self) -> float:
        return self.t[-1]

    def _add(self, dt: float, xy: FloatArray, facing: float) -> None:
        if dt <= 1e-6:  # merge: a zero-length step just replaces the last knot's state
            self.xy[-1], self.facing[-1] = np.asarray(xy, dtype=np.float64), float(facing)
            return
        self.t.append(self.now + dt)
        self.xy.append(np.asarray(xy, dtype=np.float64))
        self.facing.append(float(facing))

    def turn_to(self, heading: float) -> None:
        current = self.facing[-1]
        delta = wrap_angle(heading - current)
        self._add(abs(delta) / self.cfg.turn_rate_rad_s, self.xy[-1], current + delta)

    def hold(self, dt: float) -> None:
        self._add(dt, self.xy[-1], self.facing[-1])

    def walk_to(self, target: FloatArray, speed: float) -> None:
        delta = np.asarray(target) - self.xy[-1]
        dist = float(np.hypot(*delta))
        if dist < 1e-6:
            return
        self.turn_to(math.atan2(delta[1], delta[0]))
        self._add(dist / speed, target, self.facing[-1])

    def look_around(self, duration: float) -> None:
        end = self.now + duration
        base = self.facing[-1]
        while self.now < end - 1e-6:
            self.hold(min(float(self.rng.uniform(*self.cfg.look_hold_range_s)), end - self.now))
            if self.now >= end - 1e-6:
                break
            heading = base + float(self.rng.uniform(-self.cfg.look_around_max_rad, self.cfg.look_around_max_rad))
            self.turn_to(heading)

    def branch(self) -> Planner:
        """A planner starting where this one ends (same world, generator and configuration)."""
        return Planner(self.world, self.rng, self.cfg, self.now, self.xy[-1], self.facing[-1])

    def commit(self, move: Planner) -> None:
        """Append the knots of ``move``, a branch of this planner's end."""
        self.xy[-1], self.facing[-1] = move.xy[0], move.facing[0]
        self.t += move.t[1:]
        self.xy += move.xy[1:]
        self.facing += move.facing[1:]

    def trajectory(self, height_m: float) -> Trajectory:
        """The knots so far as a :class:`Trajectory` of a person ``height_m`` tall."""
        return Trajectory(np.array(self.t), np.array(self.xy), np.array(self.facing), height_m)

    def speed(self) -> float:
        return float(self.rng.uniform(*self.cfg.speed_range_mps))

    def waypoint(self) -> FloatArray:
        half = self.world.room.half_extents - self.cfg.waypoint_margin_m
        return self.rng.uniform(-half, half)


def plan_trajectory(
    world: World, rng: np.random.Generator, duration_s: float, config: MotionConfig | None = None,
    start_s: float = 0.0, height_m: float | None = None,
) -> Trajectory:
    """Random motion of one person over [start_s, start_s + duration_s] (knots may run past the end).

    The person starts inside (random spot, facing anywhere) with ``start_inside_probability``, else
    outside a random door, entering within ``initial_outside_max_s``. Then, repeatedly: with
    ``exit_probability`` leave through a random door, wait outside ``outside_range_s`` and come back
    through the same door (walking outside between doors would cross the room's footprint); otherwise
    walk to a random waypoint and, with ``pause_probability``, pause there looking around.
    """
    cfg = config if config is not None else MotionConfig()
    if not (is_finite_number(duration_s) and 0 < duration_s <= 7 * 24 * 3600.0):
        raise ValueError(f"duration_s must be positive (at most a week), got {duration_s!r}")
    if not is_finite_number(start_s):
        raise ValueError(f"start_s must be finite, got {start_s!r}")
    height = float(rng.uniform(*cfg.height_range_m)) if height_m is None else float(height_m)
    end = float(start_s) + float(duration_s)
    doors = world.doors
    door = doors[0] if doors else None
    if rng.uniform() < cfg.start_inside_probability or door is None:
        half = world.room.half_extents - cfg.waypoint_margin_m
        plan = Planner(world, rng, cfg, float(start_s), rng.uniform(-half, half), float(rng.uniform(-np.pi, np.pi)))
        inside = True
    else:
        door = doors[int(rng.integers(len(doors)))]
        inward = math.atan2(door.inward_normal[1], door.inward_normal[0])
        plan = Planner(world, rng, cfg, float(start_s), door.outside_xy, inward)
        plan.hold(float(rng.uniform(0.0, cfg.initial_outside_max_s)))
        inside = False
    while plan.now < end:
        if not inside:  # back in through the door last used (``door``)
            speed = plan.speed()
            plan.walk_to(door.centre_xy, speed)
            plan.walk_to(door.inside_xy, speed)
            inside = True
            continue
        if door is not None and rng.uniform() < cfg.exit_probability:
            door = doors[int(rng.integers(len(doors)))]
            speed = plan.speed()
            plan.walk_to(door.inside_xy, speed)
            plan.walk_to(door.centre_xy, speed)
            plan.walk_to(door.outside_xy, speed)
            plan.hold(float(rng.uniform(*cfg.outside_range_s)))
            inside = False
            continue
        plan.walk_to(plan.waypoint(), plan.speed())
        if rng.uniform() < cfg.pause_probability:
            plan.look_around(float(rng.uniform(*cfg.pause_range_s)))
    return plan.trajectory(height)


def sample_trajectories(
    trajectories: Sequence[Trajectory], t_s: NDArray[np.floating]
) -> tuple[FloatArray, FloatArray]:
    """Positions (T, P, 2) and facings (T, P) of every person at times ``t_s`` (T,)."""
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    xy = np.empty((t.size, len(trajectories), 2))
    facing = np.empty((t.size, len(trajectories)))
    for p, traj in enumerate(trajectories):
        xy[:, p], facing[:, p] = traj.sample(t)
    return xy, facing

