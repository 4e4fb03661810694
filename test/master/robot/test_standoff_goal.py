"""The stand-off goal core: where the goal goes, when it is re-issued, and each refusal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, STATE_TENTATIVE, NamedTrackRecord
from face_reid_master.robot.frames import PlanarTransform
from face_reid_master.robot.standoff_goal import DecisionKind, Refusal, StandoffGoal, StandoffGoalConfig


def _track(x: float = 0.0, y: float = 0.0, vx: float = 0.0, vy: float = 0.0, *, tid: int = 1, name: str = "Alice",
           state: int = STATE_CONFIRMED, conf: float = 0.9, face: int = 7) -> NamedTrackRecord:
    return NamedTrackRecord(tid, face, name, conf, 10, np.array([x, y]), np.array([vx, vy]), np.zeros((4, 4)), 1.7,
                            state, 0.0, 1.0)


def _goal(core: StandoffGoal, tracks: list[NamedTrackRecord], robot: tuple[float, float] | None = None,
          now: float = 0.0):
    decision = core.update(tracks, robot, now)
    assert decision.kind == DecisionKind.GOAL, decision.status_line()
    assert decision.goal is not None
    return decision.goal


def _faces_person(goal) -> None:
    """The goal's yaw points at the person, standoff away."""
    dx, dy = goal.person_x_m - goal.x_m, goal.person_y_m - goal.y_m
    assert math.atan2(dy, dx) == pytest.approx(goal.yaw_rad, abs=1e-9)


def test_walking_person_goal_is_standoff_ahead_along_the_velocity_facing_them() -> None:
    core = StandoffGoal(StandoffGoalConfig(standoff_distance_m=1.5))
    core.set_target("Alice")
    goal = _goal(core, [_track(2.0, 1.0, 0.0, 0.8)], robot=(10.0, 10.0))
    assert (goal.x_m, goal.y_m) == pytest.approx((2.0, 2.5))
    assert goal.yaw_rad == pytest.approx(-math.pi / 2)
    assert goal.heading_from == "velocity" and goal.track_id == 1 and goal.face_id == 7 and goal.name == "Alice"
    _faces_person(goal)


def test_standing_person_goal_is_towards_the_robot_else_the_last_heading() -> None:
    core = StandoffGoal(StandoffGoalConfig(min_speed_for_heading_m_s=0.2, min_goal_interval_s=0.0))
    core.set_target("alice")
    goal = _goal(core, [_track(0.0, 0.0, 0.1, 0.0)], robot=(0.0, -4.0))  # slower than the threshold
    assert (goal.x_m, goal.y_m) == pytest.approx((0.0, -1.0)) and goal.heading_from == "robot"
    _faces_person(goal)
    # robot unknown now: the last heading is kept (she moved, so a new goal)
    goal = _goal(core, [_track(1.0, 0.0)], robot=None, now=1.0)
    assert (goal.x_m, goal.y_m) == pytest.approx((1.0, -1.0)) and goal.heading_from == "last"
    # nothing ever known: the map's +x
    fresh = StandoffGoal()
    fresh.set_target("Alice")
    goal = _goal(fresh, [_track(1.0, 2.0)])
    assert (goal.x_m, goal.y_m, goal.yaw_rad) == pytest.approx((2.0, 2.0, math.pi)) and goal.heading_from == "default"


def test_reissued_only_when_the_person_moves_beyond_the_threshold_or_the_track_changes() -> None:
    core = StandoffGoal(StandoffGoalConfig(reissue_distance_m=0.3, min_goal_interval_s=0.5))
    core.set_target("Alice")
    first = _goal(core, [_track(0.0, 0.0, 0.5, 0.0)])
    unchanged = core.update([_track(0.2, 0.0, 0.5, 0.0)], None, 1.0)
    assert unchanged.kind == DecisionKind.UNCHANGED and unchanged.goal == first
    assert _goal(core, [_track(0.35, 0.0, 0.5, 0.0)], now=2.0).x_m == pytest.approx(1.35)
    # moved enough but too soon after the last goal: waits for min_goal_interval_s
    assert core.update([_track(1.0, 0.0, 0.5, 0.0)], None, 2.1).kind == DecisionKind.UNCHANGED
    assert core.update([_track(1.0, 0.0, 0.5, 0.0)], None, 2.6).kind == DecisionKind.GOAL
    # turning round in place moves the goal by 2 x standoff: re-issued
    assert _goal(core, [_track(1.0, 0.0, -0.5, 0.0)], now=3.5).x_m == pytest.approx(0.0)
    # a new track (she left and came back): at once, whatever the distance and interval
    assert _goal(core, [_track(1.0, 0.0, -0.5, 0.0, tid=9)], now=3.6).track_id == 9


def test_refusals_unknown_not_tracked_only_lost_and_invalid() -> None:
    core = StandoffGoal()
    core.set_target("Bob")
    seen = core.update([_track(name="Alice")], None, 0.0)
    assert seen.kind == DecisionKind.REFUSED and seen.reason == Refusal.UNKNOWN_NAME and seen.goal is None
    assert "refused 'Bob': unknown name" in seen.status_line()
    core.add_known_names(["bob"])  # e.g. a learned face of the master
    assert core.update([_track(name="Alice")], None, 0.0).reason == Refusal.NOT_TRACKED
    lost = core.update([_track(name="Bob", state=STATE_LOST, tid=4)], None, 0.0)
    assert lost.reason == Refusal.ONLY_LOST and "track 4" in lost.status_line()
    tentative = core.update([_track(name="Bob", state=STATE_TENTATIVE)], None, 0.0)
    assert tentative.reason == Refusal.NOT_TRACKED
    # a name once seen on a track is known from then on
    core.set_target("Alice")
    core.update([], None, 0.0)
    assert core.update([], None, 1.0).reason == Refusal.NOT_TRACKED
    for hostile in ("x" * 5000, "Al\x1b[2Jice", "Bob\nroot"):
        with pytest.raises(ValueError, match="name") as err:
            core.set_target(hostile)
        assert len(str(err.value)) < 150 and "\x1b" not in str(err.value) and "\n" not in str(err.value)
    assert core.target == "Alice"  # a refused name does not change the target
    core.set_target("")
    assert core.update([_track()], None, 0.0).kind == DecisionKind.IDLE


def test_tentative_tracks_count_when_configured() -> None:
    core = StandoffGoal(StandoffGoalConfig(accept_tentative=True))
    core.set_target("Alice")
    assert _goal(core, [_track(state=STATE_TENTATIVE)]).track_id == 1


def test_names_match_trimmed_and_case_insensitively_and_the_best_confirmed_track_wins() -> None:
    core = StandoffGoal()
    assert core.set_target("  aLiCe \t") == "aLiCe"
    tracks = [_track(0.0, 0.0, tid=1, conf=0.95, name="Alice", state=STATE_LOST),
              _track(5.0, 0.0, tid=2, conf=0.6, name=" ALICE"),
              _track(9.0, 0.0, tid=3, conf=0.8, name="alice"),
              _track(3.0, 3.0, tid=4, conf=0.99, name="Bob")]
    assert _goal(core, tracks).track_id == 3


def test_non_finite_tracks_are_skipped_and_counted() -> None:
    core = StandoffGoal()
    core.set_target("Alice")
    bad = [_track(float("nan"), 0.0, tid=1), _track(0.0, 0.0, float("inf"), 0.0, tid=2)]
    assert core.update(bad, None, 0.0).reason == Refusal.UNKNOWN_NAME
    assert core.tracks_skipped_not_finite == 2
    assert _goal(core, [*bad, _track(1.0, 1.0, tid=3)], robot=(float("nan"), 0.0)).heading_from == "default"


def test_goal_is_in_the_map_frame() -> None:
    world_to_map = PlanarTransform(3.0, -2.0, math.radians(90.0))
    core = StandoffGoal(StandoffGoalConfig(standoff_distance_m=1.0), world_to_map)
    core.set_target("Alice")
    goal = _goal(core, [_track(1.0, 0.0, 0.5, 0.0)])  # world: person (1, 0) walking +x, goal (2, 0)
    assert (goal.person_x_m, goal.person_y_m) == pytest.approx(tuple(world_to_map.apply(np.array([1.0, 0.0]))))
    assert (goal.x_m, goal.y_m) == pytest.approx((3.0, 0.0))  # R90 (2, 0) + (3, -2)
    assert goal.yaw_rad == pytest.approx(-math.pi / 2)  # facing world -x = map -y
    _faces_person(goal)
    # the robot's position is given in the map frame: towards it in the world
    robot_map = tuple(world_to_map.apply(np.array([1.0, 5.0])))
    goal = _goal(core, [_track(1.0, 0.0, tid=2)], robot_map)
    assert goal.heading_from == "robot"
    assert (goal.x_m, goal.y_m) == pytest.approx(tuple(world_to_map.apply(np.array([1.0, 1.0]))))


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ValueError, match="standoff_distance_m"):
        StandoffGoalConfig(standoff_distance_m=-1.0)
    with pytest.raises(ValueError, match="reissue_distance_m"):
        StandoffGoalConfig(reissue_distance_m=float("nan"))
    with pytest.raises(ValueError, match="world_to_map"):
        StandoffGoal(world_to_map="identity")  # type: ignore[arg-type]
