"""A navigation goal next to a named person: where a robot should stand to face them (pure core of face-reid-goto).

Two calls: :meth:`StandoffGoal.set_target` (a name) and :meth:`StandoffGoal.update` (the current tracks of
/tracks_named, the robot's position if known, the time) -> a :class:`Decision`: a goal to publish, "unchanged"
(the last goal still holds), or a refusal with its reason. The goal is ``standoff_distance_m`` in front of the
person (their heading: the velocity when walking, towards the robot when standing, else the last heading),
facing them, in the robot's map frame (world -> map :class:`~face_reid_master.robot.frames.PlanarTransform`).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import is_finite_number, shown
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, STATE_TENTATIVE, NamedTrackRecord
from face_reid_master.robot.frames import PlanarTransform

__all__ = [
    "Decision",
    "DecisionKind",
    "Goal",
    "Refusal",
    "StandoffGoal",
    "StandoffGoalConfig",
    "name_key",
]

MAX_NAME_CHARS = 200  # longer target names are refused (a person's name never is this long)


class Refusal(enum.Enum):
    """Why there is no goal (the value is the status text's reason)."""

    UNKNOWN_NAME = "unknown name"
    NOT_TRACKED = "not tracked"
    ONLY_LOST = "only a lost track"
    INVALID_NAME = "invalid name"


class DecisionKind(enum.Enum):
    GOAL = "goal"  # publish this goal
    UNCHANGED = "unchanged"  # the last goal still holds: publish nothing
    REFUSED = "refused"  # no goal: see the reason
    IDLE = "idle"  # no target set


@dataclass(frozen=True)
class StandoffGoalConfig:
    """Where the goal goes relative to the person and when it is re-issued."""

    standoff_distance_m: float = param(1.0, "Goal distance in front of the person (m).", low=0.0, high=20.0)
    reissue_distance_m: float = param(
        0.3, "A new goal is issued when the person, or the goal point, moved further than this since the last "
             "goal (m).", low=0.0, high=100.0)
    min_goal_interval_s: float = param(
        0.5, "At most one goal per this interval, unless the track changed (s; 0 = no limit).", low=0.0, high=3600.0)
    min_speed_for_heading_m_s: float = param(
        0.2, "From this speed on the person's heading is their velocity; slower: towards the robot (m/s).",
        low=0.0, high=10.0)
    accept_tentative: bool = param(False, "Tentative (not yet confirmed) tracks count as tracked (bool).")

    def __post_init__(self) -> None:
        validate_fields(self)


@dataclass(frozen=True)
class Goal:
    """A goal pose in the map frame (facing the person) and who it is for."""

    x_m: float
    y_m: float
    yaw_rad: float
    track_id: int
    face_id: int
    name: str
    person_x_m: float  # the person, map frame
    person_y_m: float
    heading_from: str  # "velocity", "robot", "last" or "default" (nothing known yet: the map's +x)


@dataclass(frozen=True)
class Decision:
    """What :meth:`StandoffGoal.update` decided; :meth:`status_line` is the one-line status."""

    kind: DecisionKind
    target: str = ""
    goal: Goal | None = None
    reason: Refusal | None = None
    detail: str = ""

    def status_line(self) -> str:
        who = shown(self.target, 64)
        if self.kind == DecisionKind.IDLE:
            return "no target: no goals"
        if self.reason is not None:
            return f"refused {who}: {self.reason.value}" + (f" ({self.detail})" if self.detail else "")
        g = self.goal
        if g is None:
            return f"{who}: unchanged"
        verb = "goal for" if self.kind == DecisionKind.GOAL else "goal holds for"
        return (f"{verb} {who} (track {g.track_id}, face {g.face_id}): x={g.x_m:.2f} y={g.y_m:.2f} "
                f"yaw={math.degrees(g.yaw_rad):.0f} deg, person at x={g.person_x_m:.2f} y={g.person_y_m:.2f} "
                f"(heading from {g.heading_from})")


def name_key(name: str) -> str:
    """How names are compared: trimmed, case-insensitive."""
    return name.strip().casefold()


class StandoffGoal:
    """Goals to one named person; see the module docstring."""

    def __init__(self, config: StandoffGoalConfig | None = None, world_to_map: PlanarTransform | None = None) -> None:
        self.config = config or StandoffGoalConfig()
        if not isinstance(self.config, StandoffGoalConfig):
            raise ValueError(f"config must be a StandoffGoalConfig, got {type(config).__name__}")
        self.world_to_map = world_to_map or PlanarTransform.identity()
        if not isinstance(self.world_to_map, PlanarTransform):
            raise ValueError(f"world_to_map must be a PlanarTransform, got {type(world_to_map).__name__}")
        self._map_to_world = self.world_to_map.inverse()
        self.target = ""
        self._known: dict[str, str] = {}  # name key -> name as last seen
        self._last: Goal | None = None
        self._last_person_world: NDArray[np.float64] | None = None
        self._last_goal_s = -math.inf
        self._heading_world: tuple[float, float] | None = None  # unit vector, kept per target
        self.tracks_skipped_not_finite = 0

    # ------------------------------------------------------------------ inputs
    def set_target(self, name: str) -> str:
        """Follow ``name`` from now on ('' = nobody; the next update issues a goal at once); returns it trimmed.
        ValueError (the name shown cut and escaped) for control characters or more than MAX_NAME_CHARS."""
        if not isinstance(name, str):
            raise ValueError(f"name must be a str, got {type(name).__name__}")
        clean = name.strip()
        if len(clean) > MAX_NAME_CHARS:
            raise ValueError(f"name is longer than {MAX_NAME_CHARS} characters: {shown(clean, 40)}")
        if any(not ch.isprintable() for ch in clean):
            raise ValueError(f"name has control characters: {shown(clean, 40)}")
        # a request, even for the same person, gets a fresh goal at once
        self._last, self._last_person_world, self._heading_world = None, None, None
        self._last_goal_s = -math.inf
        self.target = clean
        return clean

    def add_known_names(self, names: Iterable[str]) -> None:
        """Names of people the system knows (e.g. the master's learned faces): asking for one of them while
        nobody of that name is tracked is "not tracked", not "unknown name"."""
        for name in names:
            self._remember(name)

    def _remember(self, name: object) -> None:
        if isinstance(name, str) and 0 < len(name.strip()) <= MAX_NAME_CHARS and name.isprintable():
            self._known[name_key(name)] = name.strip()

    # ------------------------------------------------------------------ the decision
    def update(self, tracks: Sequence[NamedTrackRecord], robot_xy_map: tuple[float, float] | None,
               now_s: float) -> Decision:
        """The decision for the current tracks (all of them, as last published), the robot's position in the map
        frame (None = unknown) and the time (s, any clock that only moves forward)."""
        if not self.target:
            return Decision(DecisionKind.IDLE)
        key = name_key(self.target)
        mine = []
        for t in tracks:
            if not (np.isfinite(t.position_xy).all() and np.isfinite(t.velocity_xy).all()):
                self.tracks_skipped_not_finite += 1
                continue
            self._remember(t.name)
            if name_key(t.name) == key:
                mine.append(t)
        live_states = {STATE_CONFIRMED, STATE_TENTATIVE} if self.config.accept_tentative else {STATE_CONFIRMED}
        live = [t for t in mine if t.state in live_states]
        if not live:
            self._last = None  # the next live track gets a goal at once
            if key not in self._known:
                return self._refuse(Refusal.UNKNOWN_NAME)
            if any(t.state == STATE_LOST for t in mine):
                return self._refuse(Refusal.ONLY_LOST, f"track {max(t.track_id for t in mine)}")
            if mine:
                return self._refuse(Refusal.NOT_TRACKED, "only a tentative track")
            return self._refuse(Refusal.NOT_TRACKED)
        track = max(live, key=lambda t: (t.state == STATE_CONFIRMED, t.identity_confidence, t.track_id))
        goal = self._goal_for(track, robot_xy_map)
        if self._should_issue(track, goal, now_s):
            self._last, self._last_person_world, self._last_goal_s = goal, track.position_xy.copy(), now_s
            return Decision(DecisionKind.GOAL, self.target, goal)
        return Decision(DecisionKind.UNCHANGED, self.target, self._last)

    def _refuse(self, reason: Refusal, detail: str = "") -> Decision:
        return Decision(DecisionKind.REFUSED, self.target, reason=reason, detail=detail)

    def _should_issue(self, track: NamedTrackRecord, goal: Goal, now_s: float) -> bool:
        last, person = self._last, self._last_person_world
        if last is None or person is None or last.track_id != track.track_id:
            return True
        if now_s - self._last_goal_s < self.config.min_goal_interval_s:
            return False
        limit = self.config.reissue_distance_m
        return (float(np.hypot(*(track.position_xy - person))) > limit
                or math.hypot(goal.x_m - last.x_m, goal.y_m - last.y_m) > limit)

    def _heading(self, track: NamedTrackRecord,
                 robot_xy_map: tuple[float, float] | None) -> tuple[tuple[float, float], str]:
        """The person's heading in the world frame (unit vector) and where it came from."""
        vx, vy = (float(v) for v in track.velocity_xy)
        speed = math.hypot(vx, vy)
        if speed >= self.config.min_speed_for_heading_m_s and speed > 0.0:
            return (vx / speed, vy / speed), "velocity"
        if robot_xy_map is not None and all(is_finite_number(v) for v in robot_xy_map):
            rx, ry = (float(v) for v in self._map_to_world.apply(np.asarray(robot_xy_map, dtype=np.float64)))
            dx, dy = rx - float(track.position_xy[0]), ry - float(track.position_xy[1])
            dist = math.hypot(dx, dy)
            if dist > 1e-6:
                return (dx / dist, dy / dist), "robot"
        if self._heading_world is not None:
            return self._heading_world, "last"
        c, s = math.cos(-self.world_to_map.yaw_rad), math.sin(-self.world_to_map.yaw_rad)
        return (c, s), "default"  # the map's +x, in the world frame

    def _goal_for(self, track: NamedTrackRecord, robot_xy_map: tuple[float, float] | None) -> Goal:
        (hx, hy), source = self._heading(track, robot_xy_map)
        self._heading_world = (hx, hy)
        d = self.config.standoff_distance_m
        person_map = self.world_to_map.apply(track.position_xy)
        goal_map = self.world_to_map.apply(track.position_xy + d * np.array([hx, hy]))
        face_map = self.world_to_map.rotate(np.array([-hx, -hy]))  # from the goal towards the person
        return Goal(float(goal_map[0]), float(goal_map[1]), math.atan2(float(face_map[1]), float(face_map[0])),
                    int(track.track_id), int(track.face_id), track.name.strip(),
                    float(person_map[0]), float(person_map[1]), source)
