"""Static clutter: a person-sized object that never moves and never shows a face stops being published after
static_clutter_after_s; a walking person, a person who showed a face, and anything with the rule off stay."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.records import CameraFrameRecord, PersonRecord


def _face() -> np.ndarray:
    v = np.random.default_rng(3).normal(size=128)
    return (1.4 * v / np.linalg.norm(v)).astype(np.float32)


def _run(seconds: float, **config) -> tuple[MasterCore, dict[str, int]]:
    """A coat stand at (2, 2), a faceless person walking to and fro around (6, 0), a person standing at (-3, 1)
    with a face."""
    core = MasterCore(MasterConfig(embedding_space="dlib_resnet_v1", body_appearance_tracking=False, **config))
    face = _face()
    ids: dict[str, int] = {}
    for k in range(int(seconds * 10)):
        t = 100.0 + 0.1 * k
        people = (PersonRecord(np.array([2.0, 2.0, 0.0]), 0.05, 1.7),
                  # walks 2 m away and back every 31 s: back where it appeared now and then, still a person
                  PersonRecord(np.array([6.0 + 2.0 * np.sin(0.02 * k), 0.0, 0.0]), 0.05, 1.7),
                  PersonRecord(np.array([-3.0, 1.0, 0.0]), 0.05, 1.75, face if k % 10 == 0 else None, 0.9, 0.8))
        core.process_frame(CameraFrameRecord("cam", t, people), now_s=t)
    for tr in core.tracker.snapshots(None, include_tentative=False):
        x, y = tr.position_xy
        ids["stand" if abs(x - 2) < 0.5 and abs(y - 2) < 0.5 else "face" if x < 0 else "walker"] = tr.track_id
    return core, ids


def test_a_coat_stand_is_hidden_after_a_minute_and_people_are_not() -> None:
    core, ids = _run(70.0)
    published = {t.track_id for t in core.tracks()}
    assert set(ids) == {"stand", "walker", "face"}
    assert ids["stand"] not in published and {ids["walker"], ids["face"]} <= published
    assert core.static_clutter_tracks == 1


def test_before_the_time_or_with_the_rule_off_everything_is_published() -> None:
    core, ids = _run(30.0)
    assert ids["stand"] in {t.track_id for t in core.tracks()}
    core, ids = _run(70.0, static_clutter_after_s=0.0)
    assert ids["stand"] in {t.track_id for t in core.tracks()} and core.static_clutter_tracks == 0


def test_the_rule_is_checked_by_name() -> None:
    with pytest.raises(ValueError, match="static_clutter_radius_m"):
        MasterConfig(static_clutter_radius_m=0.0)
