"""face-reid-demo --floor-plan: the picture of a run, from constructed /tracks_named messages (no DDS)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from conftest import FACES_DIR

from face_reid_master.demo import scenario as demo_scenario
from face_reid_master.demo.floor_plan import UNDECIDED, draw_floor_plan, published_points
from face_reid_master.evaluation.published_tracks import TrackMessage
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, NamedTrackRecord


def _track(tid: int, xy: np.ndarray, face: int, name: str, state: int = STATE_CONFIRMED) -> NamedTrackRecord:
    return NamedTrackRecord(track_id=tid, face_id=face, name=name, identity_confidence=0.9 if face else 0.0,
                            face_observations=3, position_xy=xy, velocity_xy=np.zeros(2), covariance=np.eye(4),
                            height_m=1.7, state=state, first_seen_s=9.0, last_seen_s=10.0, cameras=("camera1",))


def test_the_floor_plan_shows_each_label_where_its_tracks_were(tmp_path: Path) -> None:
    scenario = demo_scenario.build_scenario(FACES_DIR, demo_scenario.DEFAULT_SEED)
    xy, inside = scenario.true_xy(np.array([10.0]))
    people = np.flatnonzero(inside[0])
    assert people.size >= 2
    a, b = (xy[0, p] for p in people[:2])
    messages = [TrackMessage(10.0, (_track(1, a, 1, "Alice"), _track(2, b, 0, ""), _track(3, b, 2, "", STATE_LOST)))]
    points = published_points(messages)
    assert set(points) == {"Alice", UNDECIDED}  # a lost track is a prediction: not drawn
    np.testing.assert_allclose(points["Alice"], [a])
    out = tmp_path / "plan.png"
    draw_floor_plan(scenario, messages, out)
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] == 800 and image.shape[0] >= 400
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20  # drawn, not blank
