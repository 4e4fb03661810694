"""``face-reid-demo``: the whole suite live over DDS on one machine, with a built-in pixel-level scenario.

Processes (each in its own process group, all on a private ROS domain with discovery limited to
loopback): per camera an RGB-D *player* (:mod:`face_reid_master.sim.rgbd_player`, the camera's sensor:
renders the camera's frames in real time with licensed face photos pasted on the heads) and a
``face-reid-camera`` node (the real camera pipeline); one ``face-reid-master`` (Bayesian face table,
predefined people from a gallery folder, a temporary face database). This process subscribes to
``/tracks_named``, prints a live table of who is where and, at the end, a summary of the re-identifications
and names against the ground truth (metrics of :mod:`face_reid_master.evaluation.evaluate`).

The scenario (:func:`build_scenario`) is scripted so that things happen on screen: people walk to spots
where a camera sees their face and look at it for a few seconds, each leaves the room through a door once,
waits outside and comes back (a new track that must get the same face id); some of them are predefined
people (gallery photos never shown in the scene), so names appear.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import signal
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from face_reid_master.demo.children import ChildProcess, child_env, read_events, start_child, stop_children
from face_reid_master.evaluation.published_tracks import (
    TrackMessage,
    nearest_person,
    run_log_from_messages,
    track_from_msg,
)
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, NamedTrackRecord
from face_reid_master.sim.rgbd_player import PhotoSpan, PlayedPerson, PlayerSpec
from face_reid_master.sim.world import (
    Door,
    Room,
    SimCamera,
    Trajectory,
    VisibilityConfig,
    World,
    camera_visibility,
    count_losses,
    make_world,
    sample_trajectories,
)

__all__ = [
    "DEFAULT_IDENTITIES",
    "DemoPerson",
    "DemoScenario",
    "build_run_log",
    "build_scenario",
    "choose_identities",
    "display_name",
    "format_summary",
    "format_table",
    "main",
    "summarize",
]

# The built-in cast, in order (the first --gallery-people of them are predefined people, named through the
# gallery): LFW identities whose rendered faces the embedder tells apart well and whose gallery photos match
# their rendered faces (measured on the real camera pipeline).
DEFAULT_IDENTITIES = ("lfw_Colin_Powell", "lfw_Ariel_Sharon", "lfw_Vladimir_Putin", "lfw_Jacques_Chirac",
                      "lfw_Hugo_Chavez", "lfw_Arnold_Schwarzenegger")
DEFAULT_SEED = 4
MIN_PHOTOS = 4  # an identity needs >= 4 photos: some for the gallery, the rest shown in the scene
_PALETTE = ((40, 60, 170), (150, 90, 30), (40, 140, 60), (130, 50, 130), (30, 150, 170), (90, 90, 90))
_LEGS = ((50, 40, 35), (70, 60, 50), (40, 40, 60), (60, 50, 45), (30, 30, 30), (80, 70, 60))
_HAIR = ((30, 40, 55), (20, 20, 25), (60, 70, 90), (40, 50, 60), (25, 30, 40), (90, 100, 110))
_ROOM_FOR_CAMERAS = {1: (5.0, 4.0), 2: (6.0, 5.0), 3: (7.0, 5.5), 4: (8.0, 6.0)}
_GT_RATE_HZ = 10.0


# ---------------------------------------------------------------------------------------------------
# Identities and photos


def display_name(identity: str) -> str:
    """A person's name from an identity folder: ``lfw_Tony_Blair`` -> ``Tony Blair``."""
    name = identity
    for prefix in ("lfw_", "deepface_", "facerec_"):
        if name.startswith(prefix):
            name = name[len(prefix):]
            break
    name = name.replace("_", " ").strip()
    return name.title() if name.islower() else name


def choose_identities(faces_dir: Path, count: int) -> list[tuple[str, list[Path]]]:
    """``count`` identity folders with >= MIN_PHOTOS photos: the built-in cast first, then others by name."""
    from face_reid_camera.faces.photos import list_identity_photos

    photos, _ = list_identity_photos(faces_dir)
    usable = {name: files for name, files in photos.items() if len(files) >= MIN_PHOTOS}
    order = [n for n in DEFAULT_IDENTITIES if n in usable] + sorted(n for n in usable if n not in DEFAULT_IDENTITIES)
    if len(order) < count:
        raise ValueError(
            f"faces folder {faces_dir} has {len(order)} identities with >= {MIN_PHOTOS} photos, the demo needs "
            f"{count} (one sub-folder of face photos per person)"
        )
    return [(name, usable[name]) for name in order[:count]]


# ---------------------------------------------------------------------------------------------------
# The scripted scenario


@dataclass(frozen=True)
class DemoPerson:
    """One person of the demo: identity, name, photos (gallery / shown in the scene), motion, visits."""

    gt_id: int
    identity: str
    name: str
    in_gallery: bool
    scene_photos: tuple[Path, ...]
    gallery_photos: tuple[Path, ...]
    trajectory: Trajectory
    visits: tuple[tuple[float, float], ...]  # (enter_s, leave_s) spans inside the room (times at the door)
    photo_spans: tuple[tuple[PhotoSpan, ...], ...]  # per camera
    colours: tuple[tuple[int, int, int], tuple[int, int, int], tuple[int, int, int]]  # body, legs, hair


@dataclass(frozen=True)
class DemoScenario:
    """The static world, the people and the timing of one demo run."""

    seed: int
    duration_s: float
    world: World
    people: tuple[DemoPerson, ...]

    @property
    def cameras(self) -> tuple[SimCamera, ...]:
        return self.world.cameras

    def true_xy(self, t_s: NDArray[np.floating]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """True positions (T, P, 2) and in-room flags (T, P) at scene times ``t_s``."""
        xy, _ = sample_trajectories([p.trajectory for p in self.people], np.asarray(t_s, dtype=np.float64))
        return xy, self.world.room.contains(xy)

    def visibility(self, t_s: NDArray[np.floating]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """(detectable by some camera, face visible to some camera), each (T, P), analytic."""
        t = np.asarray(t_s, dtype=np.float64)
        xy, facing = sample_trajectories([p.trajectory for p in self.people], t)
        inside = self.world.room.contains(xy)
        heights = np.array([p.trajectory.height_m for p in self.people])
        det = np.zeros(inside.shape, dtype=bool)
        face = np.zeros(inside.shape, dtype=bool)
        for cam in self.world.cameras:
            vis = camera_visibility(cam, xy, facing, heights, inside, VisibilityConfig(max_face_range_m=3.8))
            det |= vis.detectable
            face |= vis.face_visible
        return det, face

    def player_spec(self, camera_index: int, rate_hz: float) -> PlayerSpec:
        """What the player of camera ``camera_index`` renders (phases interleave the cameras' frames)."""
        cam = self.world.cameras[camera_index]
        people = tuple(
            PlayedPerson(p.gt_id, p.trajectory, p.photo_spans[camera_index], *p.colours) for p in self.people
        )
        room = self.world.room
        return PlayerSpec(
            cam.camera_id, cam.intrinsics, cam.xyz_rpy, (room.width_m, room.depth_m), people, self.duration_s,
            rate_hz, camera_index / (rate_hz * len(self.world.cameras)),
            float(max(room.width_m, room.depth_m) + 4.0), self.seed * 100 + camera_index,
        )


class _Script:
    """Knots of one person's motion: walk (turning first), turn, hold."""

    def __init__(self, t0: float, xy: NDArray[np.float64], facing: float) -> None:
        self.t, self.xy, self.facing = [t0], [np.asarray(xy, dtype=np.float64)], [float(facing)]

    @property
    def now(self) -> float:
        return self.t[-1]

    def _add(self, dt: float, xy: NDArray[np.float64], facing: float) -> None:
        if dt > 1e-6:
            self.t.append(self.now + dt)
            self.xy.append(np.asarray(xy, dtype=np.float64))
            self.facing.append(float(facing))

    def hold(self, dt: float) -> None:
        self._add(dt, self.xy[-1], self.facing[-1])

    def turn_to(self, heading: float, rate_rad_s: float = 3.0) -> None:
        delta = (heading - self.facing[-1] + math.pi) % (2 * math.pi) - math.pi
        self._add(abs(delta) / rate_rad_s, self.xy[-1], self.facing[-1] + delta)

    def walk_to(self, target: NDArray[np.float64], speed_mps: float) -> None:
        delta = np.asarray(target, dtype=np.float64) - self.xy[-1]
        dist = float(np.hypot(*delta))
        if dist < 1e-6:
            return
        self.turn_to(math.atan2(delta[1], delta[0]))
        self._add(dist / speed_mps, target, self.facing[-1])

    def branch(self) -> _Script:
        """A new script starting where this one ends (a move to try before committing it)."""
        return _Script(self.now, self.xy[-1], self.facing[-1])

    def commit(self, move: _Script) -> None:
        """Append a branch's knots."""
        self.t += move.t[1:]
        self.xy += move.xy[1:]
        self.facing += move.facing[1:]

    def trajectory(self, height_m: float) -> Trajectory:
        return Trajectory(np.array(self.t), np.array(self.xy), np.array(self.facing), height_m)


_MIN_GAP_M = 0.8  # people planned later keep this far from those planned before (no walking through people)


def _min_gap(world: World, move: _Script, others: Sequence[Trajectory], tail_s: float = 1.5) -> float:
    """Smallest distance (m) between ``move`` (then standing still for ``tail_s``, time to plan the next move)
    and an already planned person while both are in the room."""
    if not others or move.now <= move.t[0]:
        return math.inf
    t = np.append(np.arange(move.t[0], move.now + tail_s, 0.1), move.now + tail_s)
    mine = Trajectory(np.array(move.t), np.array(move.xy), np.array(move.facing), 1.7).sample(t)[0]
    theirs, _ = sample_trajectories(others, t)
    both = world.room.contains(theirs, -0.3) & world.room.contains(mine, -0.3)[:, None]
    dist = np.where(both, np.linalg.norm(theirs - mine[:, None, :], axis=2), np.inf)
    return float(dist.min())


def _clear(world: World, move: _Script, others: Sequence[Trajectory]) -> bool:
    """Whether ``move`` keeps >= _MIN_GAP_M from every already planned person while both are in the room."""
    return _min_gap(world, move, others) >= _MIN_GAP_M


def _face_spots(world: World, camera: SimCamera, min_range_m: float = 1.4, max_range_m: float = 3.2) -> NDArray:
    """Floor points where a lone person (1.6-1.9 m tall) facing ``camera`` shows it a usable face."""
    half = world.room.half_extents - 0.6
    xs, ys = np.arange(-half[0], half[0] + 1e-9, 0.25), np.arange(-half[1], half[1] + 1e-9, 0.25)
    pts = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 1, 2)
    to_cam = camera.position[:2] - pts[:, 0]
    facing = np.arctan2(to_cam[:, 1], to_cam[:, 0])[:, None]
    ok = np.ones(pts.shape[0], dtype=bool)
    for height in (1.6, 1.9):
        vis = camera_visibility(camera, pts, facing, np.array([height]), np.ones((pts.shape[0], 1), dtype=bool))
        ok &= vis.face_visible[:, 0] & (vis.range_m[:, 0] >= min_range_m) & (vis.range_m[:, 0] <= max_range_m)
    return pts[ok, 0]


def _doors(room: Room, cameras: Sequence[SimCamera], count: int, rng: np.random.Generator) -> tuple[Door, ...]:
    """``count`` doors spread along the walls (>= 1 m from corners and cameras, as far apart as possible): one per
    person, so that nobody comes in where somebody else just left."""
    perimeter = room.perimeter_m
    cands = []
    for s_m in np.arange(0.0, perimeter, 0.25):
        xy, normal = room.wall_point(float(s_m))
        tangent = np.array([-normal[1], normal[0]])
        corner = abs(float(room.half_extents @ tangent)) - abs(float(xy @ tangent))  # along the wall to a corner
        far = all(np.linalg.norm(xy - cam.position[:2]) >= 1.2 for cam in cameras)
        if corner >= 1.0 and far:
            cands.append((xy, normal))
    if len(cands) < count:
        raise ValueError(f"room {room.width_m} x {room.depth_m} m has no room for {count} doors")
    chosen = [int(rng.integers(len(cands)))]
    pts = np.array([c[0] for c in cands])
    while len(chosen) < count:
        dist = np.min(np.linalg.norm(pts[:, None, :] - pts[chosen][None, :, :], axis=2), axis=1)
        chosen.append(int(np.argmax(dist)))
    return tuple(Door(cands[k][0].copy(), cands[k][1].copy()) for k in chosen)


def _plan_person(world: World, rng: np.random.Generator, index: int, count: int, duration_s: float,
                 spots: list[NDArray], others: Sequence[Trajectory]
                 ) -> tuple[Trajectory, tuple[tuple[float, float], ...]]:
    """One person's script: in the room (from the start or entering by door ``index``), visits face spots looking
    at a camera, leaves once by that door, waits outside, comes back and visits spots until the end. Every move
    keeps clear of the people planned before (``others``): a blocked spot is not chosen, a blocked door is waited
    for. Returns the trajectory and the visits (times at the door)."""
    n_cams = len(world.cameras)
    speed = float(rng.uniform(0.8, 1.2))
    height = float(rng.uniform(1.62, 1.88))
    door = world.doors[index]
    inward = math.atan2(door.inward_normal[1], door.inward_normal[0])
    visits: list[tuple[float, float]] = []
    script = _Script(0.0, door.outside_xy, inward)
    if index % 2 == 0:  # already in the room, somewhere a camera sees
        cam_spots = spots[index % n_cams]
        for k in rng.permutation(len(cam_spots)):
            script = _Script(0.0, cam_spots[int(k)], float(rng.uniform(-math.pi, math.pi)))
            probe = script.branch()
            probe.hold(3.0)
            if _clear(world, probe, others):
                break
        enter = 0.0
    else:  # enters through the door shortly after the start
        script.hold(1.0 + 1.5 * index)
        enter = -1.0

    def wait(dt: float) -> None:
        """Stay put for ``dt``, or step aside if someone planned before comes this way."""
        best = script.branch()
        best.hold(dt)
        gap = _min_gap(world, best, others)
        if gap < _MIN_GAP_M and world.room.contains(script.xy[-1]):
            half = world.room.half_extents - 0.5
            for k in range(60):  # widening circles of places to step to
                reach = 1.0 + 2.0 * k / 60
                target = np.clip(script.xy[-1] + rng.uniform(-reach, reach, 2), -half, half)
                move = script.branch()
                move.walk_to(target, speed)
                move.hold(dt)
                move_gap = _min_gap(world, move, others)
                if move_gap > gap:
                    best, gap = move, move_gap
                if gap >= _MIN_GAP_M:
                    break
        script.commit(best)

    def through_door(points: Sequence[NDArray[np.float64]]) -> None:
        for attempt in range(40):  # wait (0.5 s at a time) until the way through the door is clear
            move = script.branch()
            for pt in points:
                move.walk_to(pt, speed)
            if attempt == 39 or _clear(world, move, others):
                break
            wait(0.5)
        script.commit(move)

    step_in_s = float(np.linalg.norm(door.inside_xy - door.centre_xy)) / speed
    if enter < 0:
        through_door([door.centre_xy, door.inside_xy])
        enter = script.now - step_in_s
    # exits are staggered over the first half so that everybody has time to come back and be recognised
    exit_at = duration_s * (0.16 + 0.22 * index / max(1, count - 1))
    visit = index

    def visit_spot(until: float) -> None:
        nonlocal visit
        cam = visit % n_cams
        visit += 1
        cands = spots[cam]
        dist = np.linalg.norm(cands - script.xy[-1], axis=1)
        order = [int(k) for k in rng.permutation(len(cands)) if dist[k] > 1.0]
        for k in order[:25]:
            move = script.branch()
            move.walk_to(cands[k], speed)
            to_cam = world.cameras[cam].position[:2] - cands[k]
            move.turn_to(math.atan2(to_cam[1], to_cam[0]) + float(rng.uniform(-0.25, 0.25)))
            move.hold(min(float(rng.uniform(2.5, 4.0)), max(0.5, until - move.now)))
            if _clear(world, move, others):
                script.commit(move)
                return
        wait(0.5)  # every spot is taken for now

    while script.now < exit_at:
        visit_spot(exit_at)
    through_door([door.inside_xy, door.centre_xy])
    visits.append((enter, script.now))
    script.walk_to(door.outside_xy, speed)
    script.turn_to(inward)
    script.hold(float(rng.uniform(4.5, 6.0)))
    through_door([door.centre_xy, door.inside_xy])
    visits.append((script.now - step_in_s, math.inf))
    while script.now < duration_s + 2.0:
        visit_spot(duration_s + 2.0)
    return script.trajectory(height), tuple(visits)


def _scenario_ok(scenario: DemoScenario) -> bool:
    """The script avoids what makes a tracker cut or swap tracks (the demo is about re-identification; the
    evaluation measures the hard cases): nobody comes within 0.6 m of anybody, appears where somebody else just
    disappeared or hides > 0.8 s in the middle of the room. Every person shows a face >= 2 s in each visit and
    comes back early enough to be re-identified on screen (>= 12 s before the end of a 50 s scenario)."""
    t = np.arange(0.0, scenario.duration_s, 1.0 / _GT_RATE_HZ)
    xy, inside = scenario.true_xy(t)
    n = len(scenario.people)
    for a in range(n):  # nobody walks through anybody (the planner dodges; this catches what it could not)
        for b in range(a + 1, n):
            both = inside[:, a] & inside[:, b]
            if both.any() and np.linalg.norm(xy[both, a] - xy[both, b], axis=1).min() < 0.6:
                return False
    det, face = scenario.visibility(t)
    # nobody appears to the cameras (after >= 2 s unseen) within 2 m of where somebody else disappeared up to 4.5 s
    # before (or 2 s after): the tracker would take one for the other
    appear, vanish = [], []  # (person, time, x, y)
    for p, segs in enumerate(count_losses(t, det.T, min_gap_s=2.0).segments):
        for a, b in segs:
            appear.append((p, a, *xy[round(a * _GT_RATE_HZ), p]))
            vanish.append((p, b, *xy[round(b * _GT_RATE_HZ), p]))
    if appear and vanish:
        ap, va = np.array(appear, dtype=np.float64), np.array(vanish, dtype=np.float64)
        dt = ap[:, None, 1] - va[None, :, 1]
        near = np.hypot(ap[:, None, 2] - va[None, :, 2], ap[:, None, 3] - va[None, :, 3]) < 2.0
        if np.any((dt > -2.0) & (dt < 4.5) & near & (ap[:, None, 0] != va[None, :, 0])):
            return False
    # nobody hides > 0.8 s in the middle of a visit (seen before and after): the tracker would cut the track
    for p in range(n):
        hidden = np.concatenate([[False], inside[:, p] & ~det[:, p], [False]]).astype(np.int8)
        starts, ends = np.flatnonzero(np.diff(hidden) == 1), np.flatnonzero(np.diff(hidden) == -1)
        for a, b in zip(starts, ends, strict=True):
            if a > 0 and b < t.size and det[a - 1, p] and det[b, p] and (b - a) / _GT_RATE_HZ > 0.8:
                return False
    for p, person in enumerate(scenario.people):
        if len(person.visits) < 2 or person.visits[1][0] > scenario.duration_s - max(8.0, 0.24 * scenario.duration_s):
            return False
        for a, b in person.visits:
            span = (t >= a) & (t < b)
            if face[span, p].sum() / _GT_RATE_HZ < 2.0:
                return False
    return True


def build_scenario(faces_dir: Path, seed: int = DEFAULT_SEED, num_cameras: int = 2, num_people: int = 4,
                   gallery_people: int = 2, duration_s: float = 50.0, max_tries: int = 60) -> DemoScenario:
    """The demo scenario of ``seed``: or, if that seed's random script misses a check (a face not shown long
    enough, a return too late), the first following seed that passes (``DemoScenario.seed`` says which)."""
    for name, value, low, high in (("num_cameras", num_cameras, 1, 4), ("num_people", num_people, 1, 6),
                                   ("gallery_people", gallery_people, 0, num_people)):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    if not (isinstance(duration_s, int | float) and math.isfinite(duration_s) and 20.0 <= duration_s <= 600.0):
        raise ValueError(f"duration_s must be within [20, 600] s, got {duration_s!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    cast = choose_identities(faces_dir, num_people)
    room = Room(*_ROOM_FOR_CAMERAS[num_cameras])
    for s in range(seed, seed + max_tries):
        world = make_world(num_cameras, np.random.default_rng([s, 0]), room=room)
        world = World(room, world.cameras, _doors(room, world.cameras, num_people, np.random.default_rng([s, 2])))
        spots = [_face_spots(world, cam) for cam in world.cameras]
        if any(len(sp) < 4 for sp in spots):
            continue
        people: list[DemoPerson] = []
        for p, (identity, photos) in enumerate(cast):
            traj, visits = _plan_person(world, np.random.default_rng([s, 1, p]), p, num_people, duration_s, spots,
                                        [q.trajectory for q in people])
            in_gallery = p < gallery_people
            n_gallery = min(4, len(photos) // 2) if in_gallery else 0
            scene = tuple(photos[: len(photos) - n_gallery])
            gallery = tuple(photos[len(photos) - n_gallery:])
            # one photo per camera for the whole run (one day: same look on a return; the cameras' different
            # viewpoints and lighting are stood for by different photos)
            per_cam = tuple((PhotoSpan(-1e9, 1e9, str(scene[(p + c) % len(scene)])),) for c in range(num_cameras))
            colours = (_PALETTE[p % len(_PALETTE)], _LEGS[p % len(_LEGS)], _HAIR[p % len(_HAIR)])
            people.append(DemoPerson(p, identity, display_name(identity), in_gallery, scene, gallery, traj, visits,
                                     per_cam, colours))
        scenario = DemoScenario(s, float(duration_s), world, tuple(people))
        if _scenario_ok(scenario):
            return scenario
    raise ValueError(f"no usable demo scenario for seeds {seed}..{seed + max_tries - 1} with {num_people} people in "
                     f"{duration_s:g} s: give them more time (longer duration) or take fewer people")


# ---------------------------------------------------------------------------------------------------
# What the master published, and the summary


def build_run_log(scenario: DemoScenario, messages: Sequence[TrackMessage], method: str = "bayes") -> Any:
    """A :class:`~face_reid_master.evaluation.evaluate.RunLog` from the published tracks (each confirmed track
    attributed to the nearest true person: see
    :func:`~face_reid_master.evaluation.published_tracks.run_log_from_messages`)."""
    return run_log_from_messages(messages, scenario.true_xy, len(scenario.people),
                                 ((1, 0.0, scenario.duration_s, tuple(p.gt_id for p in scenario.people)),), method)


def summarize(scenario: DemoScenario, messages: Sequence[TrackMessage], method: str = "bayes") -> dict[str, Any]:
    """Per-person and total metrics of a run (JSON-ready): tracks, re-identifications correct / wrong /
    pending, names right / wrong / none, mean re-identification time, and the evaluation's totals."""
    from face_reid_master.evaluation.evaluate import evaluate_run, evaluated_tracks, track_outcomes

    log = build_run_log(scenario, messages, method)
    t = np.arange(0.0, scenario.duration_s, 1.0 / _GT_RATE_HZ)
    detectable, _ = scenario.visibility(t)
    losses = count_losses(t, detectable.T, min_gap_s=1.5)
    gallery = {p.name: p.gt_id for p in scenario.people if p.in_gallery}
    totals = evaluate_run(log, gallery_people=gallery, with_mot=False,
                          scenario_summary={"losses": losses.total_losses, "visible_segments": losses.total_segments})
    outcomes = track_outcomes(log)
    evaluated = {tr.track_id: tr for tr in evaluated_tracks(log)}
    people = []
    for person in scenario.people:
        mine = [o for o in outcomes if o.person == person.gt_id]
        reid = [o for o in mine if o.reid_case]
        times = [o.decided_s - o.birth_s for o in reid if o.outcome == "success" and o.decided_s is not None]
        right = wrong = none = 0
        for o in mine:
            names = evaluated[o.track_id].names
            if any(n != person.name for n in names) or (names and not person.in_gallery):
                wrong += 1
            elif person.name in names:
                right += 1
            else:
                none += 1
        face_ids = sorted({o.face_id for o in mine if o.face_id})
        people.append({
            "name": person.name, "gt_id": person.gt_id, "in_gallery": person.in_gallery,
            "returns": len(person.visits) - 1, "tracks": len(mine), "face_ids": face_ids,
            "reid_correct": sum(o.outcome == "success" for o in reid),
            "reid_wrong": sum(o.outcome == "failure" for o in reid),
            "reid_pending": sum(o.outcome == "none" for o in reid),
            "names_right": right, "names_wrong": wrong, "names_none": none,
            "mean_reid_time_s": round(float(np.mean(times)), 2) if times else None,
        })
    errors = []
    if messages:
        for tr in evaluated.values():
            if tr.path:
                ts = np.array([s for s, _, _ in tr.path])
                est = np.array([[x, y] for _, x, y in tr.path])
                xy, _ = scenario.true_xy(ts)
                errors.extend(np.linalg.norm(est - xy[:, tr.true_person], axis=1).tolist())
    return {
        "seed": scenario.seed, "duration_s": scenario.duration_s, "cameras": len(scenario.cameras),
        "method": method, "messages": len(messages), "people": people,
        "false_tracks": totals["tracker"]["false_positive_tracks"],
        "median_position_error_m": round(float(np.median(errors)), 3) if errors else None,
        "reidentification": totals["reidentification"], "predefined_people": totals["predefined_people"],
        "first_appearance": totals["first_appearance"], "faces": totals["faces"],
    }


def _who(tr: NamedTrackRecord) -> str:
    if tr.name:
        return tr.name
    return f"face {tr.face_id}" if tr.face_id else "?"


_STATES = {0: "tentative", STATE_CONFIRMED: "confirmed", STATE_LOST: "lost"}


def format_table(scenario: DemoScenario, msg: TrackMessage | None, elapsed_s: float, compact: bool = False) -> str:
    """The live table: one row per published track (who, confidence, where, cameras, state, truth)."""
    head = f"t = {elapsed_s:5.1f} s / {scenario.duration_s:.0f} s"
    if msg is None:
        return f"{head}: no /tracks_named message yet"
    xy, inside = scenario.true_xy(np.array([msg.stamp_s]))
    rows = []
    for tr in sorted(msg.tracks, key=lambda r: r.track_id):
        gt = nearest_person(np.asarray(tr.position_xy, dtype=np.float64), xy[0], inside[0])
        truth = scenario.people[gt].name if gt >= 0 else "-"
        rows.append((tr, truth))
    if compact:
        parts = [f"#{tr.track_id} {_who(tr)} ({tr.identity_confidence:.2f}) at ({tr.position_xy[0]:+.1f}, "
                 f"{tr.position_xy[1]:+.1f}) [{_STATES.get(tr.state, tr.state)}; truth: {truth}]" for tr, truth in rows]
        return f"{head}: {len(rows)} tracks" + ("; " + "; ".join(parts) if parts else "")
    lines = [f"{head}   {len(rows)} tracks on /tracks_named",
             f"{'track':>5}  {'who':<18} {'conf':>5}  {'x m':>6} {'y m':>6}  {'cameras':<18} {'state':<9}  truth"]
    for tr, truth in rows:
        cams = ",".join(tr.cameras) or "-"
        lines.append(f"{tr.track_id:>5}  {_who(tr):<18.18} {tr.identity_confidence:>5.2f}  {tr.position_xy[0]:>6.2f} "
                     f"{tr.position_xy[1]:>6.2f}  {cams:<18.18} {_STATES.get(tr.state, str(tr.state)):<9}  {truth}")
    return "\n".join(lines)


def format_summary(summary: dict[str, Any]) -> str:
    """The end-of-run summary as plain text."""
    lines = [
        f"Summary: {summary['duration_s']:.0f} s, {summary['cameras']} cameras, {len(summary['people'])} people "
        f"(seed {summary['seed']}), master method {summary['method']}, {summary['messages']} /tracks_named messages",
        f"{'person':<24} {'tracks':>6}  {'re-id ok/wrong/pending':>22}  {'names right/wrong/none':>22}  "
        f"{'mean re-id s':>12}",
    ]
    for p in summary["people"]:
        who = p["name"] + (" (gallery)" if p["in_gallery"] else "")
        reid = f"{p['reid_correct']}/{p['reid_wrong']}/{p['reid_pending']}"
        names = f"{p['names_right']}/{p['names_wrong']}/{p['names_none']}"
        mean = f"{p['mean_reid_time_s']:.1f}" if p["mean_reid_time_s"] is not None else "-"
        lines.append(f"{who:<24} {p['tracks']:>6}  {reid:>22}  {names:>22}  {mean:>12}")
    r = summary["reidentification"]
    rate = f"{r['recover_rate']:.2f}" if r["recover_rate"] is not None else "-"
    lines.append(f"re-identifications: {r['success']} correct, {r['failure']} wrong, {r['none']} pending "
                 f"(recover rate {rate}); false tracks: {summary['false_tracks']}; median position error: "
                 f"{summary['median_position_error_m']} m")
    lines.append("(per track; people not in the gallery should get no name: 'none' is right for them)")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------
# Processes


class DemoError(RuntimeError):
    """The demo could not run (a process failed to start or died): the message says which and why."""


def _fmt(values: Sequence[float]) -> str:
    return "[" + ", ".join(f"{float(v):.6f}" for v in values) + "]"


def _make_gallery(scenario: DemoScenario, folder: Path) -> None:
    """The master's gallery folder: NAME/photo for the predefined people (photos not shown in the scene)."""
    for person in scenario.people:
        if not person.in_gallery:
            continue
        target = folder / person.name
        target.mkdir(parents=True)
        for photo in person.gallery_photos:
            shutil.copyfile(photo, target / photo.name)


class _Run:
    """One live run: children, the /tracks_named subscriber, the table and the collected messages."""

    def __init__(self, scenario: DemoScenario, args: argparse.Namespace, work: Path, out: TextIO) -> None:
        self.scenario, self.args, self.work, self.out = scenario, args, work, out
        self.children: list[ChildProcess] = []
        self.messages: list[TrackMessage] = []
        self.t0 = math.inf
        self.player_done: dict[str, dict[str, Any]] = {}
        self.interactive = out.isatty() and not os.environ.get("CI")

    # --- start-up --------------------------------------------------------------------------------
    def start(self, domain_id: int, run_id: str) -> None:
        env = child_env(domain_id, run_id)
        logs = self.work / "logs"
        logs.mkdir()
        gallery = self.work / "gallery"
        _make_gallery(self.scenario, gallery)
        master_args = ["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={self.work / 'faces.db'}",
                       "-p", "topic_discovery_period_s:=0.5", "-p", "stats_log_period_s:=10.0",
                       "-p", f"method:={self.args.method}"]
        if any(p.in_gallery for p in self.scenario.people):
            master_args += ["-p", f"gallery_path:={gallery}"]
        self.children.append(start_child("master", master_args, env, logs))
        for c, cam in enumerate(self.scenario.cameras):
            x, y, z, roll, pitch, yaw = cam.xyz_rpy
            self.children.append(start_child(f"{cam.camera_id}_node", [
                "-m", "face_reid_camera.ros.node", "--ros-args", "-r", f"__ns:=/{cam.camera_id}",
                "-p", f"camera_id:={cam.camera_id}", "-p", f"camera_pose_xyz_m:={_fmt((x, y, z))}",
                "-p", f"camera_pose_rpy_rad:={_fmt((roll, pitch, yaw))}", "-p", "image_qos_reliable:=true",
                "-p", "max_frame_age_s:=1.0"], env, logs))
            spec_path = self.work / f"{cam.camera_id}_player.json"
            spec_path.write_text(json.dumps(self.scenario.player_spec(c, self.args.rate_hz).to_json()))
            self.children.append(start_child(f"{cam.camera_id}_player", [
                "-m", "face_reid_master.sim.rgbd_player", "--spec", str(spec_path),
                "--truth", str(self.work / f"{cam.camera_id}_truth.npz"),
                "--ros-args", "-r", f"__ns:=/{cam.camera_id}"], env, logs, talk=True))
        for child in self.players:
            threading.Thread(target=read_events, args=(child,), daemon=True).start()

    @property
    def players(self) -> list[ChildProcess]:
        return [c for c in self.children if c.name.endswith("_player")]

    def check_alive(self) -> None:
        for child in self.children:
            code = child.proc.poll()
            if code is None or (child in self.players and child.name in self.player_done):
                continue
            if child in self.players and code == 0 and time.time() > self.t0 + self.scenario.duration_s - 1:
                continue
            raise DemoError(f"{child.name} exited with status {code}; last lines of {child.log_path}:\n"
                            f"{child.log_tail()}")

    # --- ROS -----------------------------------------------------------------------------------------
    def ros_loop(self) -> None:
        import rclpy
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions

        from face_reid_msgs.msg import NamedTrackArray

        rclpy.init(args=["face_reid_demo"], signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("face_reid_demo")
        try:
            qos = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
            got_any = [False]

            def on_tracks(msg: Any) -> None:
                got_any[0] = True
                if not math.isfinite(self.t0):
                    return
                stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 - self.t0
                tracks = tuple(track_from_msg(t, lambda s: s - self.t0) for t in msg.tracks)
                self.messages.append(TrackMessage(stamp, tracks))

            node.create_subscription(NamedTrackArray, "/tracks_named", on_tracks, qos)
            self._wait_ready(node, rclpy, got_any)
            self._play(node, rclpy)
        finally:
            node.destroy_node()
            rclpy.try_shutdown()

    def _wait_ready(self, node: Any, rclpy: Any, got_any: list[bool]) -> None:
        """Until every player's camera node listens, the master publishes and subscribes to every camera."""
        deadline = time.monotonic() + self.args.startup_timeout_s
        ready: set[str] = set()
        self.say(f"starting {len(self.children)} processes (master, {len(self.scenario.cameras)} camera nodes and "
                 f"their RGB-D players) ...")
        t_start = time.monotonic()
        while True:
            rclpy.spin_once(node, timeout_sec=0.1)
            self.check_alive()
            for child in self.players:
                while not child.events.empty():
                    event = child.events.get()
                    if event.get("event") == "ready":
                        ready.add(child.name)
                    elif event.get("event") == "error":
                        raise DemoError(f"{child.name}: {event.get('message')}\n{child.log_tail()}")
            topics = [f"/{cam.camera_id}/face_reid/frames" for cam in self.scenario.cameras]
            master_listens = all(node.count_subscribers(t) >= 1 for t in topics)
            if len(ready) == len(self.players) and got_any[0] and master_listens:
                break
            if time.monotonic() > deadline:
                waiting = [c.name for c in self.players if c.name not in ready]
                if not got_any[0]:
                    waiting.append("master (no /tracks_named yet)")
                elif not master_listens:
                    waiting.append("master (not subscribed to every camera topic)")
                tails = "\n".join(f"  {c.name}:\n{c.log_tail(8)}" for c in self.children)
                raise DemoError(f"start-up took longer than {self.args.startup_timeout_s:g} s, still waiting for "
                                f"{', '.join(waiting)}; logs:\n{tails}")
        self.say(f"all processes up in {time.monotonic() - t_start:.1f} s; playing the scenario")

    def _play(self, node: Any, rclpy: Any) -> None:
        self.t0 = time.time() + 0.5
        for child in self.players:
            assert child.proc.stdin is not None
            child.proc.stdin.write(f"start {self.t0:.6f}\n")
            child.proc.stdin.flush()
        period = 1.0 if self.interactive else 5.0
        next_print = self.t0 + period
        end = self.t0 + self.scenario.duration_s + 1.5  # the last frames still reach the master
        while time.time() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
            self.check_alive()
            for child in self.players:
                while not child.events.empty():
                    event = child.events.get()
                    if event.get("event") == "done":
                        self.player_done[child.name] = event
            now = time.time()
            if now >= next_print:
                next_print += period
                last = self.messages[-1] if self.messages else None
                table = format_table(self.scenario, last, now - self.t0, compact=not self.interactive)
                if self.interactive:
                    self.out.write(f"\x1b[H\x1b[2Jface-reid-demo: who is where (Ctrl-C stops)\n{table}\n")
                else:
                    self.out.write(table + "\n")
                self.out.flush()
        deadline = time.time() + 5.0
        while len(self.player_done) < len(self.players) and time.time() < deadline:
            for child in self.players:
                while not child.events.empty():
                    event = child.events.get()
                    if event.get("event") == "done":
                        self.player_done[child.name] = event
            time.sleep(0.05)

    def say(self, text: str) -> None:
        print(f"[face-reid-demo] {text}", file=self.out, flush=True)


# ---------------------------------------------------------------------------------------------------
# Entry point


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="face-reid-demo",
        description="Run the face-reid suite live on this machine: simulated RGB-D cameras (licensed face photos "
                    "rendered in real time) -> camera nodes -> master, over DDS on loopback only. Prints who is "
                    "where every second and a summary of the re-identifications at the end (about a minute).",
    )
    p.add_argument("--duration-s", type=float, default=50.0, help="scenario length in seconds (default 50)")
    p.add_argument("--cameras", type=int, default=2, help="number of cameras, 1-4 (default 2)")
    p.add_argument("--people", type=int, default=4, help="people in the scene, 1-6 (default 4)")
    p.add_argument("--gallery-people", type=int, default=2,
                   help="how many of them are predefined people with a name (default 2)")
    p.add_argument("--rate-hz", type=float, default=5.0, help="frames per second rendered per camera (default 5)")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"scenario seed (default {DEFAULT_SEED})")
    p.add_argument("--method", choices=("bayes", "threshold"), default="bayes", help="master face classification")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID for all the demo's processes (default: random in 1..100)")
    p.add_argument("--faces", type=Path, default=None,
                   help="face photo folder, one sub-folder per person (default: the licensed photos shipped)")
    p.add_argument("--keep-db", action="store_true",
                   help="keep the temporary folder (face database, gallery, logs) instead of deleting it")
    p.add_argument("--json", type=Path, default=None, help="also write the summary as JSON to this file")
    p.add_argument("--startup-timeout-s", type=float, default=90.0, help="give up if start-up takes longer")
    return p


class _Terminated(Exception):
    """SIGTERM received: clean up like Ctrl-C."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the demo; exit status 0 done, 1 failure of a process, 2 bad arguments, 130 interrupted."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C works even if started with SIGINT ignored
    out = sys.stdout
    if args.domain_id is not None and not 0 <= args.domain_id <= 101:
        print(f"face-reid-demo: --domain-id must be in 0..101, got {args.domain_id}", file=sys.stderr)
        return 2
    if not (math.isfinite(args.rate_hz) and 0.5 <= args.rate_hz <= 30):
        print(f"face-reid-demo: --rate-hz must be in [0.5, 30], got {args.rate_hz}", file=sys.stderr)
        return 2
    from face_reid_camera.common.resources import demo_faces_dir

    faces = args.faces if args.faces is not None else demo_faces_dir()
    if not faces.is_dir():
        print(f"face-reid-demo: no face photos at {faces}: run from a source checkout or a `pip install .` "
              "(which installs share/face_reid/demo_faces), or pass --faces DIR", file=sys.stderr)
        return 2
    try:
        scenario = build_scenario(faces, args.seed, args.cameras, args.people, args.gallery_people, args.duration_s)
    except ValueError as exc:
        print(f"face-reid-demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    domain_id = args.domain_id if args.domain_id is not None else random.randint(1, 100)
    run_id = uuid.uuid4().hex[:12]
    # this process joins the same private, loopback-only domain before rclpy is imported
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    work = Path(tempfile.mkdtemp(prefix="face-reid-demo-"))
    run = _Run(scenario, args, work, out)
    cast = ", ".join(f"{p.name}{' (gallery)' if p.in_gallery else ''}" for p in scenario.people)
    seed_note = f" (seed {args.seed} skipped: script checks failed)" if scenario.seed != args.seed else ""
    run.say(f"scenario seed {scenario.seed}{seed_note}: {scenario.duration_s:.0f} s, room "
            f"{scenario.world.room.width_m:g} x {scenario.world.room.depth_m:g} m, {len(scenario.cameras)} cameras at "
            f"{args.rate_hz:g} Hz, people: {cast}")
    run.say(f"ROS_DOMAIN_ID={domain_id}, discovery on localhost only; work folder {work}")

    def on_term(signum: int, frame: Any) -> None:
        raise _Terminated()

    previous = signal.signal(signal.SIGTERM, on_term)
    status = 0
    started = time.monotonic()
    try:
        run.start(domain_id, run_id)
        run.ros_loop()
    except DemoError as exc:
        print(f"face-reid-demo: FAILED: {exc}", file=sys.stderr, flush=True)
        status = 1
    except (KeyboardInterrupt, _Terminated):
        print("\nface-reid-demo: interrupted, stopping every process", file=sys.stderr, flush=True)
        status = 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up short
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        stop_children(run.children)
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        if status == 0:
            summary = summarize(scenario, run.messages, args.method)
            summary["wall_time_s"] = round(time.monotonic() - started, 1)
            summary["domain_id"] = domain_id
            summary["players"] = {name: {k: v for k, v in ev.items() if k != "event"}
                                  for name, ev in sorted(run.player_done.items())}
            if run.interactive:
                out.write("\n")
            out.write(format_summary(summary) + "\n")
            for name, ev in summary["players"].items():
                out.write(f"{name}: {ev.get('frames')} frames rendered, {ev.get('skipped')} skipped (late), "
                          f"{ev.get('mean_render_ms')} ms per render\n")
            out.write(f"wall time {summary['wall_time_s']:.1f} s\n")
            out.flush()
            if args.json is not None:
                args.json.write_text(json.dumps(summary, indent=2))
    finally:
        if args.keep_db:
            print(f"face-reid-demo: kept {work} (faces.db, gallery/, logs/)", file=out, flush=True)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
