"""The demo's scripted scene: who plays, where the doors are, and each person's motion.

Scripted so that things happen on screen: people walk to spots where a camera sees their face and look at
it for a few seconds, each leaves the room through a door once, waits outside and comes back (a new track
that must get the same face id); some of them are predefined people (gallery photos never shown in the
scene), so names appear. Everybody wears clothes of their own (:data:`OUTFITS`, made-up textures the players
draw), so the cameras describe bodies and the master can tell people apart by them too. Motion is built with the
simulator's :class:`~face_reid_master.sim.motion.Planner`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from face_reid_master.sim.motion import MotionConfig, Planner, Trajectory, sample_trajectories
from face_reid_master.sim.rgbd_player import PhotoSpan, PlayedPerson, PlayerSpec
from face_reid_master.sim.visibility import VisibilityConfig, camera_views, count_losses, lone_person_visibility
from face_reid_master.sim.world import Door, Room, SimCamera, World, make_world

__all__ = [
    "DEFAULT_IDENTITIES",
    "DEFAULT_SEED",
    "OUTFITS",
    "DemoPerson",
    "DemoScenario",
    "build_scenario",
    "choose_identities",
    "display_name",
    "duration_range_text",
    "min_duration_s",
]

# The built-in cast, in order (the first --gallery-people of them are predefined people, named through the
# gallery): LFW identities whose rendered faces the embedder tells apart well and whose gallery photos match
# their rendered faces (measured on the real camera pipeline).
DEFAULT_IDENTITIES = ("lfw_Colin_Powell", "lfw_Ariel_Sharon", "lfw_Vladimir_Putin", "lfw_Jacques_Chirac",
                      "lfw_Hugo_Chavez", "lfw_Arnold_Schwarzenegger")
DEFAULT_SEED = 4
MIN_PHOTOS = 4  # an identity needs >= 4 photos: some for the gallery, the rest shown in the scene
# The shortest scenario (s) the planner fits N people into, each leaving once and coming back early enough to be
# re-identified (measured from the default seed on 1-4 cameras: shorter ones found no usable script in 60 seeds).
_MIN_DURATION_S = {1: 25.0, 2: 35.0, 3: 35.0, 4: 35.0, 5: 40.0, 6: 45.0}
MAX_DURATION_S = 600.0
_MAX_PEOPLE_ONE_CAMERA = 4  # one camera's room (5 x 4 m) fits no script for 5 or 6 people (none up to 80 s)
# Everybody's clothes (BGR shirt, trousers, white stripes on the shirt): made-up textures drawn by the renderer
# (synthetic_clothes), no dataset images; shirts of different hues, plain and striped in turn, trousers unlike.
OUTFITS = (((40, 60, 170), (110, 60, 30), False), ((150, 90, 30), (90, 140, 170), True),
           ((40, 140, 60), (30, 30, 30), False), ((130, 50, 130), (120, 120, 120), True),
           ((30, 150, 170), (40, 60, 90), False), ((90, 90, 90), (50, 90, 40), True))
_HAIR = ((30, 40, 55), (20, 20, 25), (60, 70, 90), (40, 50, 60), (25, 30, 40), (90, 100, 110))
_ROOM_FOR_CAMERAS = {1: (5.0, 4.0), 2: (6.0, 5.0), 3: (7.0, 5.5), 4: (8.0, 6.0)}
_GT_RATE_HZ = 10.0
_MOTION = MotionConfig(turn_rate_rad_s=3.0)  # the demo's people turn a little slower than the simulator's
_VISIBILITY = VisibilityConfig(max_face_range_m=3.8)  # the demo's analytic face visibility


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
    clothes: tuple[tuple[int, int, int], tuple[int, int, int], bool]  # shirt, trousers (BGR), striped shirt
    hair: tuple[int, int, int]


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

    def truth_times(self) -> NDArray[np.float64]:
        """The scene times at which the ground truth is checked and evaluated (10 Hz)."""
        return np.arange(0.0, self.duration_s, 1.0 / _GT_RATE_HZ)

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
        det, face = camera_views(self.world.cameras, xy, facing, heights, inside, _VISIBILITY)
        return det.any(axis=2), face.any(axis=2)

    def player_spec(self, camera_index: int, rate_hz: float) -> PlayerSpec:
        """What the player of camera ``camera_index`` renders (phases interleave the cameras' frames)."""
        cam = self.world.cameras[camera_index]
        people = tuple(
            PlayedPerson(p.gt_id, p.trajectory, p.photo_spans[camera_index], p.clothes[0], p.clothes[1], p.hair,
                         p.clothes)
            for p in self.people
        )
        room = self.world.room
        return PlayerSpec(
            cam.camera_id, cam.intrinsics, cam.xyz_rpy, (room.width_m, room.depth_m), people, self.duration_s,
            rate_hz, camera_index / (rate_hz * len(self.world.cameras)),
            float(max(room.width_m, room.depth_m) + 4.0), self.seed * 100 + camera_index,
        )


_MIN_GAP_M = 0.8  # people planned later keep this far from those planned before (no walking through people)


def _min_gap(world: World, move: Planner, others: Sequence[Trajectory], tail_s: float = 1.5) -> float:
    """Smallest distance (m) between ``move`` (then standing still for ``tail_s``, time to plan the next move)
    and an already planned person while both are in the room."""
    if not others or move.now <= move.t[0]:
        return math.inf
    t = np.append(np.arange(move.t[0], move.now + tail_s, 0.1), move.now + tail_s)
    mine = move.trajectory(1.7).sample(t)[0]
    theirs, _ = sample_trajectories(others, t)
    both = world.room.contains(theirs, -0.3) & world.room.contains(mine, -0.3)[:, None]
    dist = np.where(both, np.linalg.norm(theirs - mine[:, None, :], axis=2), np.inf)
    return float(dist.min())


def _clear(world: World, move: Planner, others: Sequence[Trajectory]) -> bool:
    """Whether ``move`` keeps >= _MIN_GAP_M from every already planned person while both are in the room."""
    return _min_gap(world, move, others) >= _MIN_GAP_M


def _face_spots(world: World, camera: SimCamera, min_range_m: float = 1.4, max_range_m: float = 3.2) -> NDArray:
    """Floor points where a lone person (1.6-1.9 m tall) facing ``camera`` shows it a usable face."""
    half = world.room.half_extents - 0.6
    xs, ys = np.arange(-half[0], half[0] + 1e-9, 0.25), np.arange(-half[1], half[1] + 1e-9, 0.25)
    pts = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    to_cam = camera.position[:2] - pts
    facing = np.arctan2(to_cam[:, 1], to_cam[:, 0])
    ok = np.ones(pts.shape[0], dtype=bool)
    for height in (1.6, 1.9):
        vis = lone_person_visibility(camera, pts, facing, height)
        ok &= vis.face_visible[:, 0] & (vis.range_m[:, 0] >= min_range_m) & (vis.range_m[:, 0] <= max_range_m)
    return pts[ok]


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
    script = Planner(world, rng, _MOTION, 0.0, door.outside_xy, inward)
    if index % 2 == 0:  # already in the room, somewhere a camera sees
        cam_spots = spots[index % n_cams]
        for k in rng.permutation(len(cam_spots)):
            script = Planner(world, rng, _MOTION, 0.0, cam_spots[int(k)], float(rng.uniform(-math.pi, math.pi)))
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
    t = scenario.truth_times()
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


def min_duration_s(num_people: int) -> float:
    """The shortest scenario for ``num_people`` (s): see :func:`duration_range_text`."""
    return _MIN_DURATION_S[num_people]


def duration_range_text() -> str:
    """'25 s for 1 person, 35 s for 2-4, ...': the minimum as a function of people (the CLI's help, the errors)."""
    groups: dict[float, list[int]] = {}
    for people, seconds in _MIN_DURATION_S.items():
        groups.setdefault(seconds, []).append(people)
    parts = [f"{s:g} s for {p[0] if len(p) == 1 else f'{p[0]}-{p[-1]}'}" for s, p in groups.items()]
    return f"at least {', '.join(parts)} people, at most {MAX_DURATION_S:g} s"


def build_scenario(faces_dir: Path, seed: int = DEFAULT_SEED, num_cameras: int = 2, num_people: int = 4,
                   gallery_people: int = 2, duration_s: float = 50.0, max_tries: int = 60) -> DemoScenario:
    """The demo scenario of ``seed``: or, if that seed's random script misses a check (a face not shown long
    enough, a return too late), the first following seed that passes (``DemoScenario.seed`` says which)."""
    for name, value, low, high in (("num_cameras", num_cameras, 1, 4), ("num_people", num_people, 1, 6),
                                   ("gallery_people", gallery_people, 0, num_people)):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    if num_cameras == 1 and num_people > _MAX_PEOPLE_ONE_CAMERA:
        raise ValueError(f"one camera's room takes at most {_MAX_PEOPLE_ONE_CAMERA} people, got {num_people}: "
                         "use 2 or more cameras for 5 or 6 people")
    if not (isinstance(duration_s, int | float) and math.isfinite(duration_s)
            and min_duration_s(num_people) <= duration_s <= MAX_DURATION_S):
        shown = f"{duration_s:g}" if isinstance(duration_s, int | float) else repr(duration_s)
        long = isinstance(duration_s, int | float) and duration_s > MAX_DURATION_S
        raise ValueError(f"a {shown} s scenario is too {'long' if long else 'short'} for {num_people} "
                         f"{'person' if num_people == 1 else 'people'}: {duration_range_text()}")
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
            people.append(DemoPerson(p, identity, display_name(identity), in_gallery, scene, gallery, traj, visits,
                                     per_cam, OUTFITS[p % len(OUTFITS)], _HAIR[p % len(_HAIR)]))
        scenario = DemoScenario(s, float(duration_s), world, tuple(people))
        if _scenario_ok(scenario):
            return scenario
    raise ValueError(f"no usable demo scenario for seeds {seed}..{seed + max_tries - 1} with {num_people} people on "
                     f"{num_cameras} camera(s) in {duration_s:g} s: give them more time (e.g. {duration_s + 10:g} s) "
                     "or try another seed")
