"""The /people and REP-155 contents computed from master tracks (pure, no ROS)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, STATE_TENTATIVE, NamedTrackRecord
from face_reid_master.robot.frames import PlanarTransform, save_world_to_map
from face_reid_master.robot.people_outputs import PeopleOutputConfig, PeopleOutputs, hri_person_id


def _track(track_id: int, face_id: int = 0, name: str = "", state: int = STATE_CONFIRMED,
           xy: tuple[float, float] = (1.0, 2.0), v: tuple[float, float] = (0.5, 0.0), confidence: float = 0.9,
           evidence: str = "face") -> NamedTrackRecord:
    return NamedTrackRecord(track_id, face_id, name, confidence, 3, np.array(xy, dtype=float), np.array(v, dtype=float),
                            np.eye(4), 1.7, state, 0.0, 1.0, ("cam_a",), evidence if face_id else "")


def test_names_ids_and_tags_follow_the_rules() -> None:
    out = PeopleOutputs().people([_track(1, 3, "Alice"), _track(2, 4), _track(5), _track(6, state=STATE_TENTATIVE)])
    assert [p.name for p in out] == ["Alice", "face_4", "track_5"]  # the tentative track is left out
    assert [p.person_id for p in out] == ["face3", "face4", "anon5"]
    alice = out[0]
    assert alice.position_xyz_m == (1.0, 2.0, 0.0) and alice.velocity_xyz_mps == (0.5, 0.0, 0.0)
    assert alice.reliability == 1.0 and not alice.lost
    tags = dict(zip(alice.tagnames, alice.tags, strict=True))
    assert tags == {"person_id": "face3", "track_id": "1", "face_id": "3", "state": "confirmed",
                    "identity_confidence": "0.900", "identity_evidence": "face"}
    assert hri_person_id(0, 9) == "anon9" and hri_person_id(12, 9) == "face12"


def test_lost_tracks_are_flagged_with_the_lower_reliability() -> None:
    outputs = PeopleOutputs(PeopleOutputConfig(people_lost_reliability=0.25))
    (lost,) = outputs.people([_track(1, 2, state=STATE_LOST)])
    assert lost.lost and lost.reliability == 0.25
    assert dict(zip(lost.tagnames, lost.tags, strict=True))["state"] == "lost"
    (person,) = outputs.hri(outputs.people([_track(1, 2, state=STATE_LOST)]), 0.0).persons
    assert person.location_confidence == 0.25


def test_bad_positions_are_left_out_and_bad_velocities_zeroed() -> None:
    out = PeopleOutputs().people([_track(1, xy=(math.nan, 0.0)), _track(2, v=(math.inf, 0.0))])
    assert [p.track_id for p in out] == [2] and out[0].velocity_xyz_mps == (0.0, 0.0, 0.0)


def test_positions_and_velocities_go_to_the_map_frame(tmp_path: Path) -> None:
    path = tmp_path / "world_to_map.yaml"
    save_world_to_map(path, PlanarTransform(10.0, -2.0, math.pi / 2), map_frame="map")
    outputs = PeopleOutputs(PeopleOutputConfig(people_world_to_map_path=str(path)))
    (p,) = outputs.people([_track(1, xy=(1.0, 2.0), v=(0.5, 0.0))])
    assert p.position_xyz_m == pytest.approx((10.0 - 2.0, -2.0 + 1.0, 0.0))
    assert p.velocity_xyz_mps == pytest.approx((0.0, 0.5, 0.0))
    assert outputs.frame_id("world") == "map" and PeopleOutputs().frame_id("world") == "world"


def test_config_is_validated_and_a_bad_transform_file_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="people_lost_reliability"):
        PeopleOutputConfig(people_lost_reliability=1.5)
    with pytest.raises(ValueError, match="hri_max_persons"):
        PeopleOutputConfig(hri_max_persons=0)
    bad = tmp_path / "bad.yaml"
    bad.write_text("x_m: 1\n")
    with pytest.raises(ValueError, match="yaw_deg"):
        PeopleOutputs(PeopleOutputConfig(people_world_to_map_path=str(bad)))


def test_rep155_persons_anonymous_face_id_and_name() -> None:
    outputs = PeopleOutputs()
    update = outputs.hri(outputs.people([_track(1, 3, "Alice"), _track(2)]), 0.0)
    assert update.tracked == ("face3", "anon2")
    alice, anon = update.persons
    assert (alice.anonymous, alice.face_id, alice.name, alice.location_confidence) == (False, "3", "Alice", 1.0)
    assert (anon.anonymous, anon.face_id, anon.name) == (True, "", "")
    assert update.aliases == {} and update.removed == ()


def test_an_anonymous_person_that_gets_a_face_is_aliased_then_forgotten() -> None:
    outputs = PeopleOutputs(PeopleOutputConfig(hri_forget_after_s=5.0))
    outputs.hri(outputs.people([_track(7)]), 0.0)
    update = outputs.hri(outputs.people([_track(7, 2, "Bob")]), 1.0)
    assert update.tracked == ("face2",) and update.aliases == {"anon7": "face2"}
    assert set(outputs.hri_known) == {"anon7", "face2"}  # the alias stays readable for a while
    assert outputs.hri(outputs.people([_track(7, 2, "Bob")]), 4.5).removed == ()
    assert outputs.hri(outputs.people([_track(7, 2, "Bob")]), 5.5).removed == ("anon7",)
    assert outputs.hri_known == ("face2",)


def test_the_person_id_of_a_face_survives_a_new_track() -> None:
    outputs = PeopleOutputs(PeopleOutputConfig(hri_forget_after_s=5.0))
    outputs.hri(outputs.people([_track(1, 4, "Carol")]), 0.0)
    gone = outputs.hri([], 1.0)
    assert gone.tracked == () and gone.removed == ()
    back = outputs.hri(outputs.people([_track(9, 4, "Carol")]), 3.0)
    assert back.tracked == ("face4",) and back.aliases == {} and back.removed == ()


def test_two_tracks_of_one_face_make_one_rep155_person() -> None:
    outputs = PeopleOutputs()
    people = outputs.people([_track(1, 4, state=STATE_LOST, confidence=0.99), _track(2, 4, confidence=0.6),
                             _track(3, 4, confidence=0.5)])
    assert len(people) == 3  # all three are obstacles on /people
    assert [p.track_id for p in people if p.hri] == [2]  # the confirmed one holds the person
    assert outputs.hri(people, 0.0).tracked == ("face4",)


def test_remembered_persons_are_bounded() -> None:
    outputs = PeopleOutputs(PeopleOutputConfig(hri_max_persons=3, hri_forget_after_s=1000.0))
    removed: list[str] = []
    for k in range(10):
        removed += outputs.hri(outputs.people([_track(100 + k)]), float(k)).removed
    assert len(outputs.hri_known) == 3 and "anon109" in outputs.hri_known
    assert removed == [f"anon{100 + k}" for k in range(7)]  # the longest gone first
