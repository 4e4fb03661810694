"""People who keep out of each other's way: the planned motions of one day played together, giving way.

Pure numpy. :func:`~face_reid_master.sim.motion.plan_trajectory` plans each person alone, so planned paths go
through each other. :func:`keep_apart` plays everybody's plan at once in steps of ``step_s`` (0.2 s): each person
moves along their own plan, but their *progress* along it may fall behind the clock (they slow down or wait) and
they may step off it (an *offset* that fades back once the way is clear), so that no two people in the room come
closer than ``passing_distance_m`` centre to centre.

Each step, everybody whose planned step (on at full speed, the offset fading once they have not given way for a
second) is clear and comfortable takes it. *Clear*: it keeps the passing distance from everybody else's planned
step and from everybody standing still (closest approach along both straight steps, while both are in the room, so
between the steps too), or, for two people already closer, does not bring them closer. *Comfortable*: at the
velocities of the step nobody comes closer than the passing distance within ``horizon_s``. The others choose, all
at once, among: on at full or half speed or waiting, the offset fading, kept or growing by a sidestep away from or
towards the person most in the way; stepping back, forward or diagonally. Of the clear options a person takes a
comfortable one with the most progress (then the smallest offset and change of velocity), else the one keeping the
farthest away; who is stopped by a person also giving way before them yields (slows down rather than leaving the
path, makes room); nothing clear: they stand still. They choose against each other standing still; where two
choices clash, the later person chooses again against everybody's choice. Standing still is always clear, since
everybody who moved checked against it, so the distance holds at every instant. People outside the room are in
nobody's way; a step out through a door starts close to the plan.

Facing is the plan's at the person's progress (a sidestep does not turn them); people who never meet anybody
follow their plans exactly. Deterministic: no random draws.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import is_finite_number
from face_reid_master.sim.motion import PASSING_DISTANCE_RANGE_M, Trajectory
from face_reid_master.sim.visibility import BoolArray, FloatArray
from face_reid_master.sim.world import World

__all__ = ["CrowdConfig", "CrowdStats", "closest_approach", "keep_apart"]

IntArray = NDArray[np.int64]

# the options of a person giving way: progress (half steps) and how the offset changes
_FADE, _KEEP, _AWAY, _TOWARD, _BACK, _BACK_AWAY, _BACK_TOWARD, _FORWARD, _FORWARD_AWAY, _FORWARD_TOWARD = range(10)
_PROGRESS = np.array([2, 2, 2, 2, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0])
_CHANGE = np.array((_FADE, _KEEP, _AWAY, _TOWARD) * 2 + (_FADE, _AWAY, _TOWARD, _BACK, _BACK_AWAY, _BACK_TOWARD,
                                                          _FORWARD, _FORWARD_AWAY, _FORWARD_TOWARD))
_ESCAPE = np.array([False] * 11 + [True] * 6)  # may reach twice the offset limit (getting out of a jam)
_SETTLE_STEPS = 5  # an offset starts fading this many steps after its person last gave way


@dataclass(frozen=True)
class CrowdConfig:
    """How people give way (m, s, m/s)."""

    passing_distance_m: float = 0.5
    step_s: float = 0.2
    horizon_s: float = 1.5  # a move is comfortable if nobody comes closer within this (at the current velocities)
    sidestep_speed_mps: float = 0.5
    offset_fade_mps: float = 0.3  # back to the planned path once the way is clear
    max_offset_m: float = 1.5
    wall_clearance_m: float = 0.25  # sidesteps keep this far from the walls
    door_offset_m: float = 0.2  # at most this far off the plan outside the room (in a door's passage)

    def __post_init__(self) -> None:
        low, high = PASSING_DISTANCE_RANGE_M
        if not (is_finite_number(self.passing_distance_m) and low <= self.passing_distance_m <= high):
            raise ValueError(f"CrowdConfig.passing_distance_m must be within [{low}, {high}] m, got "
                             f"{self.passing_distance_m!r}")
        for name in ("step_s", "horizon_s", "sidestep_speed_mps", "offset_fade_mps", "max_offset_m",
                     "wall_clearance_m", "door_offset_m"):
            value = getattr(self, name)
            if not (is_finite_number(value) and value > 0):
                raise ValueError(f"CrowdConfig.{name} must be positive, got {value!r}")
        if self.step_s > 0.5:
            raise ValueError(f"CrowdConfig.step_s must be at most 0.5 s, got {self.step_s!r}")


@dataclass(frozen=True)
class CrowdStats:
    """What giving way cost on one day (shares of the person-steps in the room)."""

    steps: int
    slowed_share: float  # behind the plan's pace (slowing down or waiting)
    aside_share: float  # more than 0.1 m off the planned path
    stood_steps: int  # person-steps standing still because no option was clear
    max_delay_s: float  # the most anybody fell behind their plan
    closest_m: float  # the closest two people in the room came at the steps (inf: never two at once)


def _closest2(rx: FloatArray, ry: FloatArray, vx: FloatArray, vy: FloatArray, lo: FloatArray | float,
              hi: FloatArray | float) -> FloatArray:
    """Smallest squared |r + s v| over s in [lo, hi] (relative positions r, relative velocities v); inf where the
    window is empty."""
    s = -(rx * vx + ry * vy)
    s /= np.maximum(vx * vx + vy * vy, 1e-12)
    np.maximum(s, lo, out=s)
    np.minimum(s, hi, out=s)
    dx = rx + s * vx
    dy = ry + s * vy
    d2 = dx * dx + dy * dy
    if not np.isscalar(lo) or not np.isscalar(hi):
        d2[np.broadcast_to(np.less(hi, lo), d2.shape)] = np.inf
    return d2


def closest_approach(xy: NDArray[np.floating], present: NDArray[np.bool_]) -> float:
    """The smallest distance between two people present at the same sample: ``xy`` (T, P, 2), ``present`` (T, P);
    inf if no two people are ever present together."""
    pts = np.asarray(xy, dtype=np.float64)
    here = np.asarray(present, dtype=bool)
    best = math.inf
    for p in range(pts.shape[1] - 1):
        both = here[:, p, None] & here[:, p + 1:]
        if both.any():
            dist = np.hypot(pts[:, p + 1:, 0] - pts[:, p, None, 0], pts[:, p + 1:, 1] - pts[:, p, None, 1])
            best = min(best, float(dist[both].min()))
    return best


class _Crowd:
    """One day's people stepping together (see the module)."""

    def __init__(self, world: World, plans: Sequence[Trajectory], start_s: float, n_steps: int,
                 cfg: CrowdConfig) -> None:
        self.world, self.cfg = world, cfg
        self.dt = cfg.step_s
        self.c = cfg.passing_distance_m
        self.lateral = cfg.sidestep_speed_mps * cfg.step_s
        self.fade = cfg.offset_fade_mps * cfg.step_s
        n = len(plans)
        count = 2 * n_steps + 1  # progress advances in half steps: full speed, half speed, waiting
        tau = start_s + (cfg.step_s / 2.0) * np.arange(count, dtype=np.float64)
        self.plan_xy = np.empty((n, count, 2))
        self.plan_facing = np.empty((n, count))
        for p, plan in enumerate(plans):
            self.plan_xy[p, :, 0] = np.interp(tau, plan.t_s, plan.xy[:, 0])
            self.plan_xy[p, :, 1] = np.interp(tau, plan.t_s, plan.xy[:, 1])
            self.plan_facing[p] = np.interp(tau, plan.t_s, plan.facing_rad)
        self.last = count - 1
        half = world.room.half_extents
        self.present_half = half + 1e-9  # the room, as the ground truth's in_room
        self.inside_half = half - cfg.wall_clearance_m
        self.room_half = half + 1e-6
        self.people = np.arange(n)

    def present(self, xy: FloatArray) -> BoolArray:
        """Who counts (..., 2): in the room (what the cameras can see)."""
        return (np.abs(xy[..., 0]) <= self.present_half[0]) & (np.abs(xy[..., 1]) <= self.present_half[1])

    def window(self, p0: FloatArray, p1: FloatArray, in0: BoolArray | None = None, in1: BoolArray | None = None
               ) -> tuple[FloatArray, FloatArray]:
        """The part [lo, hi] of the straight step p0 -> p1 (..., 2) spent in the room (lo > hi: none); ``in0``,
        ``in1``: whether p0, p1 are in the room, if known."""
        in0 = self.present(p0) if in0 is None else in0
        in1 = self.present(p1) if in1 is None else in1
        lo = np.where(in0, 0.0, 2.0)
        hi = np.where(in1, 1.0, -1.0)
        cross = in0 != in1
        if cross.any():
            d = p1 - p0
            safe = np.where(np.abs(d) > 1e-12, d, 1e-12)
            h = self.present_half
            leave = (np.sign(p1) * h - p0) / safe  # per axis: where it crosses the wall on p1's side
            enter = (np.sign(p0) * h - p0) / safe
            out1 = np.abs(p1) > h
            out0 = np.abs(p0) > h
            exit_at = np.where(out1, leave, 1.0).min(axis=-1)
            enter_at = np.where(out0, enter, 0.0).max(axis=-1)
            hi = np.where(in0 & ~in1, np.clip(exit_at, 0.0, 1.0), hi)
            lo = np.where(in1 & ~in0, np.clip(enter_at, 0.0, 1.0), lo)
        return lo, hi

    def in_room(self, xy: FloatArray) -> BoolArray:
        return (np.abs(xy[..., 0]) <= self.room_half[0]) & (np.abs(xy[..., 1]) <= self.room_half[1])

    def place(self, plan: FloatArray, off: FloatArray, frm: FloatArray, off_before: FloatArray
              ) -> tuple[FloatArray, FloatArray, BoolArray]:
        """Where a person stepping from ``frm`` (offset ``off_before``) to plan point ``plan`` with offset ``off``
        ends (..., 2), the offset they then have, and whether they may: on a plan point outside the room (a door's
        passage) exactly, reached through the doorway with a small offset; in the room, off the walls unless the
        offset shrinks or they get no nearer to the walls."""
        size_before = np.hypot(off_before[..., 0], off_before[..., 1])
        out = ~self.in_room(plan)
        off = np.where(out[..., None], 0.0, off)
        xy = plan + off
        size = np.hypot(off[..., 0], off[..., 1])
        # in the room: off the walls, or no nearer to them than before, or back towards the plan
        wall = np.minimum(self.room_half[0] - np.abs(xy[..., 0]), self.room_half[1] - np.abs(xy[..., 1]))
        wall_before = np.minimum(self.room_half[0] - np.abs(frm[..., 0]), self.room_half[1] - np.abs(frm[..., 1]))
        ok = ~out & (wall >= 0.0) & ((size <= size_before + 1e-9) | (wall >= self.cfg.wall_clearance_m)
                                     | (wall >= wall_before - 1e-9))
        crossing = out & self.in_room(frm)  # leaving the room: through the doorway, close to the plan
        ok = ok | (out & ~crossing)
        if crossing.any():
            ok = ok | (crossing & (size_before <= self.cfg.door_offset_m) & self.world.allowed((xy + frm) / 2.0))
        return xy, off, ok

    def faded(self, off: FloatArray) -> FloatArray:
        size = np.hypot(off[..., 0], off[..., 1])[..., None]
        return off * np.maximum(1.0 - self.fade / np.maximum(size, 1e-12), 0.0)

    def choose(self, ids: IntArray, movers: IntArray, progress: IntArray, offset: FloatArray, pos: FloatArray,
               here_now: BoolArray, vel: FloatArray, move: FloatArray, expect: FloatArray, giving_way: BoolArray
               ) -> tuple[IntArray, FloatArray, FloatArray, BoolArray]:
        """The moves of ``movers`` (r,) given everybody else's ``move`` (P, 2) in this step (zero: standing still)
        and expected velocity ``expect`` (P, 2); ``giving_way`` (P,): who is choosing in this step. The P people
        are ``ids`` (their plans), at ``pos`` (in the room: ``here_now``) after a step at ``vel``; ``movers`` index
        them. Per mover, of the options that are clear: a comfortable one with the most progress (then the smallest
        offset and change of velocity); else a comfortable one standing on the plan with the smallest offset; else
        the one keeping the farthest away; none clear: standing still. Who *yields* (their person in the way also
        gives way and comes first) rather slows down than leaves the path, and, standing, keeps the farthest away
        (makes room). Returns progress (r,), offset
        (r, 2), position (r, 2) and who stood (r,)."""
        c2, dt = self.c * self.c, self.dt
        rows = np.arange(movers.size)
        j = progress[movers]
        off0 = offset[movers]
        here0 = pos[movers]
        plan = ids[movers]
        ahead = self.plan_xy[plan, np.minimum(j + 2, self.last)] - self.plan_xy[plan, j]
        size = np.hypot(ahead[:, 0], ahead[:, 1])
        facing = self.plan_facing[plan, j]
        ahead = np.where((size < 1e-6)[:, None], np.stack([np.cos(facing), np.sin(facing)], axis=-1),
                         ahead / np.maximum(size, 1e-12)[:, None])
        left = np.stack([-ahead[:, 1], ahead[:, 0]], axis=-1)
        # the person most in the way (near, and ahead rather than behind): step away from their side, or to the
        # right if they are dead ahead
        rx = pos[None, :, 0] - here0[:, None, 0]  # (r, P)
        ry = pos[None, :, 1] - here0[:, None, 1]
        dist = np.hypot(rx, ry)
        score = dist - 0.5 * (rx * ahead[:, 0, None] + ry * ahead[:, 1, None]) / np.maximum(dist, 1e-9)
        score[rows, movers] = np.inf
        k = np.argmin(score, axis=1)
        yielding = giving_way[k] & (k < movers)
        cross = ahead[:, 0] * ry[rows, k] - ahead[:, 1] * rx[rows, k]
        away = np.where((cross >= 0.0)[:, None], -left, left) * self.lateral
        back = -ahead * self.lateral
        diag = 1.0 / math.sqrt(2.0)
        changes = np.stack([self.faded(off0) - off0, np.zeros_like(away), away, -away, back, diag * (back + away),
                            diag * (back - away), -back, diag * (away - back), diag * (-away - back)],
                           axis=1)  # (r, 10, 2) in the order _FADE, _KEEP, ...
        steps = _PROGRESS
        js = np.minimum(j[:, None] + steps[None, :], self.last)
        cand, offs, ok_place = self.place(self.plan_xy[plan[:, None], js], off0[:, None, :] + changes[:, _CHANGE, :],
                                          here0[:, None, :], off0[:, None, :])  # (r, C, 2)
        size = np.hypot(offs[..., 0], offs[..., 1])
        limit = np.where(_ESCAPE, 2.0 * self.cfg.max_offset_m, self.cfg.max_offset_m)
        ok_place &= (size <= limit) | (size <= np.hypot(off0[:, 0], off0[:, 1])[:, None] + 1e-9)
        was_here = here_now[movers]
        new_others = pos + move
        here_next = self.present(new_others)
        cand_here = self.present(cand)
        o_lo, o_hi = self.window(pos, new_others, here_now, here_next)  # (P,): the part of their step in the room
        m_lo, m_hi = self.window(here0[:, None, :], cand, was_here[:, None], cand_here)  # (r, C)
        lo = np.maximum(m_lo[..., None], o_lo[None, None, :])
        hi = np.minimum(m_hi[..., None], o_hi[None, None, :])  # (r, C, P): when both are in the room
        hi[rows, :, movers] = -1.0
        floor = np.where(was_here[:, None] & here_now[None, :], np.minimum(self.c, dist - 1e-9), self.c)
        floor2 = (np.maximum(floor, 0.0) ** 2)[:, None, :]  # a pair already closer may only part
        mx = cand[..., 0] - here0[:, None, 0]  # (r, C)
        my = cand[..., 1] - here0[:, None, 1]
        hard = _closest2(rx[:, None, :], ry[:, None, :], move[None, None, :, 0] - mx[..., None],
                         move[None, None, :, 1] - my[..., None], lo, hi) >= floor2
        margin = _closest2(new_others[None, None, :, 0] - cand[..., 0, None],
                           new_others[None, None, :, 1] - cand[..., 1, None],
                           expect[None, None, :, 0] - mx[..., None] / dt, expect[None, None, :, 1] - my[..., None] / dt,
                           0.0, self.cfg.horizon_s)
        watch = cand_here[..., None] & here_next[None, None, :]
        watch[rows, :, movers] = False
        margin = np.where(watch, margin, np.inf).min(axis=2)  # (r, C) squared
        clear = ok_place & hard.all(axis=2)
        comfy = clear & (margin >= c2)
        far = np.sqrt(np.minimum(margin, 100.0))
        stay_score = np.where(yielding[:, None], far, -size)
        jerk = np.hypot(mx / dt - vel[movers, 0, None], my / dt - vel[movers, 1, None])  # change of velocity (m/s)
        # on: keeping pace (sidestepping) first, or, for who yields, leaving the path last (slowing down first)
        growth = np.maximum(size - np.hypot(off0[:, 0], off0[:, 1])[:, None], 0.0)
        on = np.where(yielding[:, None], 3.0 * steps[None, :] - 10.0 * growth, 10.0 * steps[None, :] - size)
        score = np.where(comfy & (steps[None, :] > 0), 100.0 + on - 2.0 * jerk,
                         np.where(comfy, 50.0 + stay_score, np.where(clear, far + 0.01 * steps[None, :], -np.inf)))
        pick = np.argmax(score, axis=1)
        stood = ~clear.any(axis=1)
        new_j = np.where(stood, j, js[rows, pick])
        new_off = np.where(stood[:, None], off0, offs[rows, pick])
        new_pos = np.where(stood[:, None], here0, cand[rows, pick])
        return new_j, new_off, new_pos, stood

    def step(self, progress: IntArray, offset: FloatArray, pos: FloatArray, vel: FloatArray, settled: BoolArray
             ) -> tuple[IntArray, FloatArray, FloatArray, int, BoolArray]:
        """One step of everybody: progress, offset and position after it, how many stood (no option clear) and who
        gave way. The planned step fades the offset of those ``settled`` (who have not given way for a while) and
        keeps the others' (no zigzag between sidestepping and fading back)."""
        want_j = np.minimum(progress + 2, self.last)
        want, want_off, ok_place = self.place(self.plan_xy[self.people, want_j],
                                              np.where(settled[:, None], self.faded(offset), offset), pos, offset)
        gave_way = np.zeros(progress.size, dtype=bool)
        # only people in the room (now or after the step), or who may not take their planned step, can be in the
        # way or give way: the others take their planned steps
        ids = np.flatnonzero(self.present(pos) | self.present(want) | ~ok_place)
        if ids.size < 2 and ok_place.all():
            return want_j, want_off, want, 0, gave_way
        j, off, xy, stood, gave = self.step_among(ids, progress[ids], offset[ids], pos[ids], vel[ids], want_j[ids],
                                                  want_off[ids], want[ids], ok_place[ids])
        want_j[ids], want_off[ids], want[ids] = j, off, xy
        gave_way[ids] = gave
        return want_j, want_off, want, stood, gave_way

    def step_among(self, ids: IntArray, progress: IntArray, offset: FloatArray, pos: FloatArray, vel: FloatArray,
                   want_j: IntArray, want_off: FloatArray, want: FloatArray, ok_place: BoolArray
                   ) -> tuple[IntArray, FloatArray, FloatArray, int, BoolArray]:
        """:meth:`step` for people ``ids`` (their progress, offset, position, velocity, planned step)."""
        c, dt = self.c, self.dt
        eye = np.eye(ids.size, dtype=bool)
        here_now, here_want = self.present(pos), self.present(want)
        move = want - pos
        rx = pos[None, :, 0] - pos[:, None, 0]  # (me, other)
        ry = pos[None, :, 1] - pos[:, None, 1]
        dist = np.hypot(rx, ry)
        floor = np.where(here_now[:, None] & here_now[None, :], np.minimum(c, dist - 1e-9), c)
        floor2 = np.maximum(floor, 0.0) ** 2  # a pair already closer may only part
        lo, hi = self.window(pos, want, here_now, here_want)  # the part of their step each spends in the room
        stay_lo, stay_hi = np.where(here_now, 0.0, 2.0), np.where(here_now, 1.0, -1.0)
        vx = move[None, :, 0] - move[:, None, 0]
        vy = move[None, :, 1] - move[:, None, 1]
        both_move = _closest2(rx, ry, vx, vy, np.maximum(lo[:, None], lo[None, :]),
                              np.where(eye, -1.0, np.minimum(hi[:, None], hi[None, :])))
        other_stays = _closest2(rx, ry, -np.broadcast_to(move[:, None, 0], rx.shape),
                                -np.broadcast_to(move[:, None, 1], rx.shape), np.maximum(lo[:, None], stay_lo[None, :]),
                                np.where(eye, -1.0, np.minimum(hi[:, None], stay_hi[None, :])))
        comfy = _closest2(rx + vx, ry + vy, vx / dt, vy / dt, 0.0, self.cfg.horizon_s) >= c * c
        watch = here_want[:, None] & here_want[None, :] & ~eye
        fine = (both_move >= floor2) & (other_stays >= floor2) & (comfy | ~watch)
        accept = ok_place & fine.all(axis=1)
        if accept.all():
            return want_j, want_off, want, 0, ~accept
        new_j = np.where(accept, want_j, progress)
        new_off = np.where(accept[:, None], want_off, offset)
        new_move = np.where(accept[:, None], move, 0.0)
        expect = np.where(accept[:, None], move / dt, vel)
        movers = np.flatnonzero(~accept)
        j_m, off_m, pos_m, stood = self.choose(ids, movers, progress, offset, pos, here_now, vel, new_move, expect,
                                               ~accept)
        new_j[movers], new_off[movers] = j_m, off_m
        new_pos = pos + new_move
        new_pos[movers] = pos_m
        # the movers chose against each other standing still: the later of two clashing choices chooses again
        m_move = pos_m - pos[movers]
        m_lo, m_hi = self.window(pos[movers], pos_m)
        pair_hi = np.where(np.eye(movers.size, dtype=bool), -1.0, np.minimum(m_hi[:, None], m_hi[None, :]))
        clash = _closest2(rx[np.ix_(movers, movers)], ry[np.ix_(movers, movers)],
                          m_move[None, :, 0] - m_move[:, None, 0], m_move[None, :, 1] - m_move[:, None, 1],
                          np.maximum(m_lo[:, None], m_lo[None, :]), pair_hi) < floor2[np.ix_(movers, movers)]
        again = np.triu(clash, 1).any(axis=0)
        n_stood = int(np.count_nonzero(stood & ~again))
        if again.any():
            redo = movers[again]
            new_pos[redo] = pos[redo]
            for p in redo:
                now_move = new_pos - pos
                expect[movers] = now_move[movers] / dt
                j_p, off_p, pos_p, stood_p = self.choose(ids, np.array([p]), progress, offset, pos, here_now, vel,
                                                         now_move, expect, ~accept)
                new_j[p], new_off[p], new_pos[p] = j_p[0], off_p[0], pos_p[0]
                n_stood += int(stood_p[0])
        return new_j, new_off, new_pos, n_stood, ~accept


def keep_apart(world: World, plans: Sequence[Trajectory], start_s: float, duration_s: float,
               config: CrowdConfig | None = None) -> tuple[list[Trajectory], CrowdStats]:
    """The trajectories of people following ``plans`` over [start_s, start_s + duration_s] while keeping
    ``config.passing_distance_m`` from each other (see the module); after that each plan's remaining knots
    follow, as late as its person is. Knots every ``config.step_s``."""
    cfg = config if config is not None else CrowdConfig()
    if not (is_finite_number(start_s) and is_finite_number(duration_s) and duration_s > 0):
        raise ValueError(f"keep_apart needs a finite start_s and a positive duration_s, got {start_s!r}, "
                         f"{duration_s!r}")
    n_people = len(plans)
    dt = cfg.step_s
    n_steps = math.ceil(duration_s / dt - 1e-9)
    if n_people == 0:
        return [], CrowdStats(n_steps, 0.0, 0.0, 0, 0.0, math.inf)
    clock = start_s + dt * np.arange(n_steps + 1, dtype=np.float64)
    crowd = _Crowd(world, plans, start_s, n_steps, cfg)
    progress = np.zeros(n_people, dtype=np.int64)
    offset = _initial_offsets(crowd.plan_xy[:, 0], crowd.present, cfg.passing_distance_m, crowd.inside_half)
    pos = crowd.plan_xy[:, 0] + offset
    vel = np.zeros((n_people, 2))
    out_xy = np.empty((n_steps + 1, n_people, 2))
    out_j = np.empty((n_steps + 1, n_people), dtype=np.int64)
    aside = np.zeros((n_steps + 1, n_people), dtype=bool)
    out_xy[0], out_j[0] = pos, progress
    stood = 0
    calm = np.full(n_people, _SETTLE_STEPS)  # steps since each last gave way
    for k in range(n_steps):
        progress, offset, new_pos, n_stood, gave_way = crowd.step(progress, offset, pos, vel, calm >= _SETTLE_STEPS)
        calm = np.where(gave_way, 0, calm + 1)
        vel = (new_pos - pos) / dt
        pos = new_pos
        stood += n_stood
        out_xy[k + 1], out_j[k + 1] = pos, progress
        aside[k + 1] = np.hypot(offset[:, 0], offset[:, 1]) > 0.1
    here = crowd.present(out_xy)
    closest = closest_approach(out_xy, here)
    n_here = max(int(np.count_nonzero(here[1:])), 1)
    slowed = (np.diff(out_j, axis=0) < 2) & (out_j[:-1] < crowd.last) & here[1:]
    slowed_share = float(np.count_nonzero(slowed)) / n_here
    aside_share = float(np.count_nonzero(aside[1:] & here[1:])) / n_here
    facing = crowd.plan_facing[crowd.people[None, :], out_j]  # (T, P)
    reached = start_s + (dt / 2.0) * out_j  # the plan time each person has reached (T, P)
    trajectories = []
    for p, plan in enumerate(plans):
        later = plan.t_s > reached[-1, p] + 1e-9
        t = np.concatenate([clock, plan.t_s[later] + (clock[-1] - reached[-1, p])])
        xy = np.concatenate([out_xy[:, p], plan.xy[later]])
        fac = np.concatenate([facing[:, p], plan.facing_rad[later]])
        keep = np.concatenate([[True], np.diff(t) > 1e-9])
        trajectories.append(Trajectory(t[keep], xy[keep], fac[keep], plan.height_m))
    max_delay = float(np.max(clock[:, None] - reached))
    return trajectories, CrowdStats(n_steps, slowed_share, aside_share, stood, max_delay, closest)


def _initial_offsets(xy: FloatArray, present: Callable[[FloatArray], BoolArray], c: float, half: FloatArray
                     ) -> FloatArray:
    """Offsets that part people who start closer than ``c`` (each later one moves away from the earlier ones)."""
    n = xy.shape[0]
    offset = np.zeros((n, 2))
    here = present(xy)
    for _ in range(5):
        moved = False
        for p in range(n):
            for q in range(p):
                rel = xy[p] + offset[p] - xy[q] - offset[q]
                d = float(np.hypot(*rel))
                if not (here[p] and here[q]) or d >= c:
                    continue
                away = rel / d if d > 1e-9 else np.array([math.cos(p), math.sin(p)])
                target = np.clip(xy[p] + offset[p] + (c - d + 1e-3) * away, -half, half)
                offset[p] = target - xy[p]
                moved = True
        if not moved:
            break
    return offset
