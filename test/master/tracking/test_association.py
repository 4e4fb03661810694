"""Association (tracking.association): one track per person through crossings, hand-overs, misses,
turns, noise outliers, coasting and hidden people, on the synthetic scenes of ``trajectories.py``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tracking_test_helpers import assert_one_track_per_person, det, run, snap
from trajectories import (
    CameraFov,
    Scenario,
    Walker,
    crossing_pair,
    hidden_walker_and_bystander,
    overview_camera,
    random_walkers,
)

from face_reid_master.tracking.association import gnn, swap_probabilities
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.kalman import mahalanobis_sq
from face_reid_master.tracking.records import TrackState
from face_reid_master.tracking.tracker import Tracker


def test_gnn_maximises_the_number_of_feasible_matches_then_minimises_the_cost() -> None:
    cost = np.array([[0.1, 0.2], [0.15, 9.0]])
    # Row 0 is cheapest on column 0, but row 1 can only take column 0: two matches beat one cheaper one.
    r, c = gnn(cost, np.array([[True, True], [True, False]]))
    assert sorted(zip(r.tolist(), c.tolist(), strict=True)) == [(0, 1), (1, 0)]
    r, c = gnn(cost, np.ones((2, 2), dtype=bool))
    assert sorted(zip(r.tolist(), c.tolist(), strict=True)) == [(0, 1), (1, 0)]  # 0.35 < 9.1
    r, c = gnn(cost, np.zeros((2, 2), dtype=bool))
    assert r.shape == c.shape == (0,)


# (angle, noise, closest approach): a 0 m approach means both at the crossing point at the same
# instant (physically a collision; with noise >= 0.05 m a coin flip at shallow angles, so only
# asserted at low noise and wide angles); 0.5 m is how real people pass each other.
CROSSINGS = [
    (135.0, 0.02, 0.0),
    (180.0, 0.02, 0.0),
    (20.0, 0.05, 0.5),
    (20.0, 0.1, 0.5),
    (45.0, 0.1, 0.5),
    (90.0, 0.1, 0.5),
    (135.0, 0.1, 0.5),
    (180.0, 0.1, 0.5),
    (90.0, 0.15, 0.5),
]


@pytest.mark.parametrize(("angle_deg", "noise_m", "approach_m"), CROSSINGS)
@pytest.mark.parametrize("seed", [0, 2])
def test_two_people_crossing_keep_their_ids(
    angle_deg: float, noise_m: float, approach_m: float, seed: int
) -> None:
    walkers = crossing_pair(angle_deg, min_separation_m=approach_m)
    frames = Scenario(walkers, (overview_camera(),), 5.5, noise_std_m=noise_m, seed=seed).frames()
    tracker, results = run(frames)
    assert_one_track_per_person(frames, results)
    assert tracker.stats.tracks_confirmed == 2


HANDOVER_CAMERAS = {
    # Wedges 4 m from the walking line (y = 0): A covers x <= +0.3, B covers x >= -0.3.
    "overlap": (-2.5, 2.5),
    # A covers x <= -0.3, B covers x >= +0.3: the person is unseen for 0.5 s.
    "gap": (-3.1, 3.1),
}


@pytest.mark.parametrize("layout", sorted(HANDOVER_CAMERAS))
@pytest.mark.parametrize("bias_m", [0.0, 0.1])
def test_camera_handover_keeps_one_track(layout: str, bias_m: float) -> None:
    xa, xb = HANDOVER_CAMERAS[layout]
    cams = (
        CameraFov("a", (xa, -4.0), math.pi / 2, math.radians(70), 6.0),
        CameraFov(
            "b", (xb, -4.0), math.pi / 2, math.radians(70), 6.0, phase_s=0.013, bias_xy=(bias_m, -bias_m)
        ),
    )
    walker = Walker(1, ((-5.0, 0.0), (5.0, 0.0)), 1.2)
    sc = Scenario((walker,), cams, 8.3, noise_std_m=0.05, latency_s=0.01, latency_jitter_s=0.03, seed=1)
    frames = sc.frames()
    tracker = Tracker()
    results = []
    both_seen = False
    for f in frames:
        results.append(tracker.update(f.detections, f.stamp_s, f.camera_id))
        snaps = tracker.snapshots()
        both_seen |= any(s.cameras == {"a", "b"} for s in snaps)
    assert {f.camera_id for f in frames if f.gt_ids} == {"a", "b"}
    assert_one_track_per_person(frames, results)
    assert tracker.stats.tracks_confirmed == 1
    assert both_seen == (layout == "overlap")


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_misses_and_noise_keep_one_track_per_person(seed: int) -> None:
    # miss probability 0.2, noise 0.05 m, four people turning at random, two overlapping cameras.
    cams = (
        CameraFov("a", (-6.0, 0.0), 0.0, math.radians(100), 12.0),
        CameraFov("b", (6.0, 0.0), math.pi, math.radians(100), 12.0, phase_s=0.017),
    )
    walkers = random_walkers(4, seed)
    frames = Scenario(walkers, cams, 9.0, noise_std_m=0.05, miss_probability=0.2, seed=seed).frames()
    tracker, results = run(frames)
    assert_one_track_per_person(frames, results)
    assert tracker.stats.tracks_confirmed == 4


@pytest.mark.parametrize("seed", [0, 1])
def test_six_people_with_noise_and_misses_keep_their_tracks(seed: int) -> None:
    # Harder than the spec case: noise 0.1 m, miss probability 0.2, six people.
    cams = (
        CameraFov("a", (-6.0, 0.0), 0.0, math.radians(100), 12.0),
        CameraFov("b", (6.0, 0.0), math.pi, math.radians(100), 12.0, phase_s=0.017),
    )
    walkers = random_walkers(6, seed, area_m=9.0, min_separation_m=0.5)
    frames = Scenario(walkers, cams, 9.0, noise_std_m=0.1, miss_probability=0.2, seed=seed).frames()
    tracker, results = run(frames)
    assert_one_track_per_person(frames, results)
    assert tracker.stats.tracks_confirmed == 6


@pytest.mark.parametrize(("turn_deg", "noise_m"), [(60.0, 0.02), (90.0, 0.02), (90.0, 0.05), (150.0, 0.05)])
def test_sharp_turn_keeps_the_track(turn_deg: float, noise_m: float) -> None:
    # An instant turn at 1.4 m/s outruns the tight constant-velocity gate of a precise track within
    # a few frames; the second association pass (reach from the last detection) keeps the person.
    h = math.radians(180.0 - turn_deg)
    walker = Walker(1, ((-3.0, 0.0), (0.0, 0.0), (3.0 * math.cos(h), 3.0 * math.sin(h))), 1.4)
    frames = Scenario((walker,), (overview_camera(),), walker.end_s, noise_std_m=noise_m, seed=0).frames()
    tracker, results = run(frames)
    assert_one_track_per_person(frames, results)
    assert tracker.stats.tracks_created == 1


def test_turn_during_a_detection_gap_keeps_the_track() -> None:
    # Walking +x at 1.4 m/s, unseen for 0.3 s while turning to +y: the detection is far outside
    # even the wide gate of the (precise) prediction, but within reach of the last detection.
    tracker = Tracker()
    for k in range(61):
        tracker.update([det(1.4 * k / 30, 0.0, std=0.02)], k / 30, "cam")
    for k in range(61, 69):
        tracker.update([], k / 30, "cam")
    a = snap(tracker, 1)
    z = np.array([[2.8, 0.42]])
    (d2,), _ = mahalanobis_sq(a.position_xy[None], a.position_covariance[None], z, np.array([0.02**2]))
    assert d2[0] > 2 * TrackerConfig().gate_mahalanobis_sq
    assert np.linalg.norm(a.position_xy - z[0]) > TrackerConfig().min_person_separation_m
    res = tracker.update([det(2.8, 0.42, std=0.02)], 69 / 30, "cam")
    assert res.associations == ((1, 0),) and res.created == ()


def test_noise_outlier_within_the_wide_gate_stays_with_its_track() -> None:
    tracker = Tracker()
    for k in range(30):  # a person standing still, seen at 30 Hz by a noisy (0.12 m) sensor
        tracker.update([det(0.0, 0.0, std=0.12)], k / 30, "cam")
    a = snap(tracker, 1)
    z = np.array([[0.55, 0.0]])
    (d2,), _ = mahalanobis_sq(a.position_xy[None], a.position_covariance[None], z, np.array([0.12**2]))
    gate = TrackerConfig().gate_mahalanobis_sq
    assert gate < d2[0] <= 2 * gate  # outside the 99 % gate, inside the 99.99 % one
    assert 0.55 > TrackerConfig().min_person_separation_m + TrackerConfig().max_speed_mps / 30  # beyond reach
    res = tracker.update([det(0.55, 0.0, std=0.12)], 1.0, "cam")
    assert res.associations == ((1, 0),) and res.created == ()


def test_association_cost_prefers_the_precise_track_over_the_mahalanobis_closer_vague_one() -> None:
    tracker = Tracker()
    for k in range(6):  # A: precise detections at the origin; B: a very imprecise sensor 0.9 m away
        tracker.update([det(0.0, 0.0, std=0.02), det(0.9, 0.0, std=1.0)], k / 10, "cam")
    a, b = snap(tracker, 1), snap(tracker, 2)
    assert a.state is b.state is TrackState.CONFIRMED
    z = np.array([[0.06, 0.0]])
    d2_a, _ = mahalanobis_sq(a.position_xy[None], a.position_covariance[None], z, np.array([0.02**2]))
    d2_b, _ = mahalanobis_sq(b.position_xy[None], b.position_covariance[None], z, np.array([0.02**2]))
    assert d2_b[0, 0] < d2_a[0, 0] < TrackerConfig().gate_mahalanobis_sq  # B is "closer" by d2 alone
    res = tracker.update([det(0.06, 0.0, std=0.02)], 0.5, "cam")
    assert res.associations == ((1, 0),)  # ... but d2 + log det S picks A


def test_coasting_track_does_not_take_the_detection_of_a_fresh_one() -> None:
    tracker = Tracker()
    for k in range(11):  # F stands at the origin; C walks towards it and vanishes after t = 0.5
        t = k / 10
        dets = [det(0.0, 0.0)] + ([det(2.2 - 2.0 * t, 0.0)] if t <= 0.5 else [])
        tracker.update(dets, t, "cam")
    c = snap(tracker, 2)
    assert c.state is TrackState.CONFIRMED and c.last_seen_s == 0.5
    z = np.array([[0.3, 0.0]])  # F's noisy detection: outside F's gate, inside C's
    d2_c, _ = mahalanobis_sq(c.position_xy[None], c.position_covariance[None], z, np.array([0.05**2]))
    assert d2_c[0, 0] < TrackerConfig().gate_mahalanobis_sq
    res = tracker.update([det(0.3, 0.0)], 1.1, "cam")
    assert res.associations == ((1, 0),)


def test_second_detection_next_to_a_tracked_person_starts_no_track() -> None:
    tracker = Tracker()
    for k in range(4):
        tracker.update([det(0.0, 0.0)], k / 10, "cam")
    res = tracker.update([det(0.0, 0.0), det(0.3, 0.1)], 0.4, "cam")  # a split cluster
    assert res.associations == ((1, 0),) and res.created == () and res.suppressed_detections == (1,)
    assert tracker.stats.detections_suppressed_near_track == 1 and tracker.num_tracks == 1


def test_lost_track_does_not_capture_a_newcomer_far_away() -> None:
    tracker = Tracker(TrackerConfig(lost_after_s=0.5, delete_after_s=5.0))
    for k in range(10):  # person walking +x, then disappears
        tracker.update([det(0.1 * k, 0.0)], k / 10, "cam")
    for k in range(10, 25):
        tracker.update([], k / 10, "cam")
    assert snap(tracker, 1).state is TrackState.LOST
    res = tracker.update([det(4.5, 3.0)], 2.5, "cam")  # 3+ m from anything the lost track could be
    assert res.created == (2,) and res.associations == ((2, 0),)


@pytest.mark.parametrize(("hidden_s", "offset_m"), [(0.9, 1.1), (1.2, 1.3), (1.6, 1.6)])
@pytest.mark.parametrize("seed", [0, 1])
def test_hidden_persons_track_does_not_take_a_bystander_who_appears_next_to_it(
    hidden_s: float, offset_m: float, seed: int
) -> None:
    # A person hidden for ~1 s (as behind others in a crowd) while someone steps out 1.1-1.6 m to
    # their side: the coasting/LOST track's grown gate holds both, but it must wait for its person
    # (who reappears on the predicted path) rather than swap to the bystander.
    walkers = hidden_walker_and_bystander(hidden_s, offset_m)
    frames = Scenario(walkers, (overview_camera(),), walkers[1].end_s, noise_std_m=0.05, seed=seed).frames()
    tracker, results = run(frames)
    assert_one_track_per_person(frames, results)
    assert tracker.stats.tracks_confirmed == 2


def test_the_swap_probability_of_two_tracks_is_the_exchanged_pairs_likelihood() -> None:
    nll = np.array([[1.0, 1.0], [1.0, 1.0]])  # each detection as likely for either track: a coin
    possible = np.ones((2, 2), dtype=bool)
    rows, cols = np.array([0, 1]), np.array([0, 1])
    carries = np.ones(2, dtype=bool)
    ((a, b, p),) = swap_probabilities(nll, possible, rows, cols, carries)
    assert (a, b) == (0, 1) and p == pytest.approx(0.5)
    nll = np.array([[0.0, 4.0], [4.0, 0.0]])  # exchanged pairs 8 (-2 log L) worse: exp(-4) / (1 + exp(-4))
    assert swap_probabilities(nll, possible, rows, cols, carries)[0][2] == pytest.approx(1 / (1 + math.exp(4)))
    nll = np.array([[0.0, 30.0], [30.0, 0.0]])  # far apart: below 1e-3, not reported
    assert swap_probabilities(nll, possible, rows, cols, carries) == ()
    apart = np.eye(2, dtype=bool)  # the association could not have exchanged them
    assert swap_probabilities(np.ones((2, 2)), apart, rows, cols, carries) == ()


def test_a_track_left_without_its_detection_counts_against_the_one_that_took_it() -> None:
    nll = np.array([[2.0], [2.0]])  # one detection, taken by track 0; track 1 (confirmed) as close, undetected
    pairs = swap_probabilities(nll, np.ones((2, 1), dtype=bool), np.array([0]), np.array([0]), np.ones(2, bool))
    assert pairs == ((0, 1, pytest.approx(0.5)),)
    tentative = np.array([True, False])  # an unconfirmed track carries no identity: nothing to doubt
    assert swap_probabilities(nll, np.ones((2, 1), dtype=bool), np.array([0]), np.array([0]), tentative) == ()


def test_the_tracker_reports_the_pairs_it_may_have_swapped_at_a_crossing() -> None:
    tracker = Tracker(TrackerConfig())
    swaps = []
    for k in range(40):  # two people walk towards each other along x and cross at t = 2 s
        t = k * 0.1
        xa, xb = -2.0 + t, 2.0 - t
        result = tracker.update([det(xa, 0.0), det(xb, 0.05)], t, "cam")
        swaps.extend(result.swaps)
    assert swaps, "the crossing was never reported"
    assert max(p for _, _, p in swaps) > 0.1  # at the crossing the association had a real doubt
    assert all(a != b for a, b, _ in swaps)
