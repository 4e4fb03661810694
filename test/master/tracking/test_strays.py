"""Strays (tracking.association): the probability that the detection a track took is a person it was not
following, from the pair's position likelihood and body appearance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.tracking.association import StrayModel, stray_probabilities
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.tracker import FrameStatus, Tracker

MODEL = StrayModel(log_odds=-3.0, appearance_slope=10.0, appearance_distance=0.5)
DIM = 8
LOOK = {0: np.eye(DIM, dtype=np.float32)[0] * 0.5, 1: np.eye(DIM, dtype=np.float32)[1] * 0.5}  # 0.71 apart


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def test_the_stray_probability_is_a_logistic_of_position_likelihood_and_appearance() -> None:
    nll = np.array([[0.0, 10.0]])  # the pair's d2 + log det S
    rows, cols, follows = np.array([0]), np.array([0]), np.ones(1, dtype=bool)
    ((track, p),) = stray_probabilities(MODEL, nll, None, rows, cols, follows)
    assert track == 0 and p == pytest.approx(_sigmoid(-3.0))  # no appearance: the position alone
    assert stray_probabilities(MODEL, nll, None, rows, np.array([1]), follows)[0][1] == pytest.approx(_sigmoid(2.0))
    looks = np.array([[0.9, np.nan]])  # 0.4 farther than the neutral distance: +4 log odds
    assert stray_probabilities(MODEL, nll, looks, rows, cols, follows)[0][1] == pytest.approx(_sigmoid(1.0))
    assert stray_probabilities(MODEL, nll, looks, rows, np.array([1]), follows)[0][1] == pytest.approx(_sigmoid(2.0))
    alike = np.array([[0.1, 0.1]])  # looks like the track: -4
    assert stray_probabilities(MODEL, nll, alike, rows, cols, follows) == ()  # below 1e-2: not reported
    assert stray_probabilities(MODEL, nll, None, rows, cols, np.zeros(1, dtype=bool)) == ()  # a tentative track


def test_a_track_hidden_from_the_camera_until_this_frame_is_likelier_to_have_strayed() -> None:
    model = StrayModel(log_odds=-3.0, appearance_slope=10.0, appearance_distance=0.5, occlusion_log_odds=1.5)
    nll = np.array([[0.0], [0.0]])
    rows, cols, follows = np.array([0, 1]), np.array([0, 0]), np.ones(2, dtype=bool)
    hidden = np.array([True, False])
    by_track = dict(stray_probabilities(model, nll, None, rows, cols, follows, hidden))
    assert by_track[0] == pytest.approx(_sigmoid(-1.5)) and by_track[1] == pytest.approx(_sigmoid(-3.0))
    assert dict(stray_probabilities(model, nll, None, rows, cols, follows))[0] == pytest.approx(_sigmoid(-3.0))


def _walk(tracker: Tracker, x0: float, k0: int, k1: int, look: np.ndarray | None) -> list[tuple[int, float]]:
    """One person walks +x at 0.5 m/s from ``x0`` (frames k0..k1-1, 10 per s); the strays reported."""
    strays: list[tuple[int, float]] = []
    for k in range(k0, k1):
        result = tracker.update_arrays(np.array([[x0 + 0.05 * (k - k0), 0.0]]), np.array([0.05]),
                                       np.array([np.nan]), 0.1 * k, "c", None if look is None else look[None, :])
        strays.extend(result.strays)
    return strays


@pytest.mark.parametrize("appearance", [False, True])
def test_a_track_following_its_person_never_looks_strayed(appearance: bool) -> None:
    tracker = Tracker(TrackerConfig())
    strays = _walk(tracker, 0.0, 0, 60, LOOK[0] if appearance else None)
    assert max((p for _, p in strays), default=0.0) < 0.2


@pytest.mark.parametrize("appearance", [False, True])
def test_a_track_that_takes_a_newcomer_where_its_person_left_reports_a_stray(appearance: bool) -> None:
    tracker = Tracker(TrackerConfig())
    _walk(tracker, 0.0, 0, 20, LOOK[0] if appearance else None)  # walks to x = 0.95 m by t = 1.9 s, then leaves
    (track,) = tracker.track_ids()
    # 0.4 s later someone else steps in 0.9 m to the side of where the first person was heading
    look = np.stack([LOOK[1]]) if appearance else None
    result = tracker.update_arrays(np.array([[1.15, 0.9]]), np.array([0.05]), np.array([np.nan]), 2.3, "c", look)
    assert result.track_of_detection() == {0: track}  # the track took the newcomer...
    (strayed,) = [p for t, p in result.strays if t == track]  # ...and says it probably strayed
    assert strayed > 0.5
    if appearance:  # the newcomer looks like someone else: surer than by position alone
        alone = Tracker(TrackerConfig())
        _walk(alone, 0.0, 0, 20, None)
        by_position = alone.update_arrays(np.array([[1.15, 0.9]]), np.array([0.05]), np.array([np.nan]), 2.3, "c")
        assert strayed > by_position.strays[0][1]


def _newcomer_stray(config: TrackerConfig, empty_frames: list[float]) -> float:
    """The person of :func:`_walk` leaves at 1.9 s; camera ``c`` then sends ``empty_frames`` (no detection) and at
    2.3 s sees someone else 0.9 m to the side of where the person was heading: the track's stray probability."""
    tracker = Tracker(config)
    _walk(tracker, 0.0, 0, 20, None)
    for stamp in empty_frames:
        tracker.update_arrays(np.zeros((0, 2)), np.zeros(0), np.zeros(0), stamp, "c")
    result = tracker.update_arrays(np.array([[1.15, 0.9]]), np.array([0.05]), np.array([np.nan]), 2.3, "c")
    (track,) = tracker.track_ids()
    return dict(result.strays)[track]


def test_a_track_the_camera_missed_in_its_previous_frames_reports_a_likelier_stray() -> None:
    config = TrackerConfig()
    unseen = [2.0, 2.1, 2.2]  # the camera looked and did not see the person (hidden, or gone)
    hidden = _newcomer_stray(config, unseen)
    no_frames = _newcomer_stray(config, [])  # the camera sent nothing since it last saw the person
    assert hidden > no_frames
    odds = (hidden / (1.0 - hidden)) / (no_frames / (1.0 - no_frames))
    assert math.log(odds) == pytest.approx(config.stray_occlusion_log_odds, abs=1e-6)
    off = TrackerConfig(stray_occlusion_log_odds=0.0)
    assert _newcomer_stray(off, unseen) == pytest.approx(no_frames)
    long_gone = TrackerConfig(stray_occlusion_max_s=0.3)  # unseen for 0.4 s: a person walking into view, not hidden
    assert _newcomer_stray(long_gone, unseen) == pytest.approx(no_frames)


def test_a_late_frame_finds_no_track_hidden() -> None:
    """A frame older than the camera's newest cannot tell what that camera missed since."""
    strays = []
    for config in (TrackerConfig(), TrackerConfig(stray_occlusion_log_odds=0.0)):
        tracker = Tracker(config)
        _walk(tracker, 0.0, 0, 20, None)
        for stamp in (2.0, 2.1, 2.3):
            tracker.update_arrays(np.zeros((0, 2)), np.zeros(0), np.zeros(0), stamp, "c")
        result = tracker.update_arrays(np.array([[1.15, 0.9]]), np.array([0.05]), np.array([np.nan]), 2.2, "c")
        assert result.status is FrameStatus.APPLIED_LATE
        (track,) = tracker.track_ids()
        strays.append(dict(result.strays)[track])
    assert strays[0] == pytest.approx(strays[1])
