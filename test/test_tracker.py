"""Tests of the master's multi-camera people tracker (face_reid_master.tracking.tracker / .kalman).

Behaviour tests are driven by the synthetic trajectory generator in ``trajectories.py``; the filter is
checked against filterpy's reference ``KalmanFilter``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2
from trajectories import (
    CameraFov,
    Scenario,
    SyntheticFrame,
    Walker,
    crossing_pair,
    hidden_walker_and_bystander,
    min_pair_distance,
    overview_camera,
    person_reports,
    random_walkers,
)

from face_reid_master.tracking.kalman import ConstantVelocityModel, mahalanobis_sq
from face_reid_master.tracking.tracker import (
    Detection,
    FrameStatus,
    Tracker,
    TrackerConfig,
    TrackSnapshot,
    TrackState,
    UpdateResult,
)

# ---------------------------------------------------------------------------------------------- helpers


def run(
    frames: Sequence[SyntheticFrame], config: TrackerConfig | None = None
) -> tuple[Tracker, list[UpdateResult]]:
    tracker = Tracker(config)
    return tracker, [tracker.update(f.detections, f.stamp_s, f.camera_id) for f in frames]


def det(x: float, y: float, cam: str = "cam", std: float = 0.05, **kw: object) -> Detection:
    return Detection(np.array([x, y]), cam, std, **kw)  # type: ignore[arg-type]


def snap(tracker: Tracker, track_id: int) -> TrackSnapshot:
    (s,) = [s for s in tracker.snapshots() if s.track_id == track_id]
    return s


def assert_one_track_per_person(frames: Sequence[SyntheticFrame], results: Sequence[UpdateResult]) -> None:
    reports = person_reports(frames, results)
    assert reports, "no person was tracked"
    for pid, rep in reports.items():
        assert rep.switches == 0, f"person {pid} switched track: {rep.track_sequence}"
        assert rep.dominant_fraction >= 0.95, f"person {pid}: only {rep.dominant_fraction:.2f} on one track"
        assert rep.first_track == rep.last_track == rep.dominant_track
    dominant = [rep.dominant_track for rep in reports.values()]
    assert len(set(dominant)) == len(dominant), f"two people share a track: {dominant}"


# ---------------------------------------------------------------------------------------------- Kalman


def test_vectorised_filter_matches_filterpy_reference() -> None:
    model = ConstantVelocityModel(accel_noise_mps2=0.8, init_velocity_std_mps=1.3)
    rng = np.random.default_rng(0)
    stds = np.array([0.05, 0.1, 0.2])
    z0 = rng.normal(size=(3, 2))
    refs = [model.to_filterpy(z0[k], stds[k]) for k in range(3)]
    x, P = model.initial_state(z0, stds**2)
    for _ in range(30):
        dt = rng.uniform(0.0, 0.3, size=3)  # irregular, per track
        z = rng.normal(size=(3, 2))
        x, P = model.predict(x, P, dt)
        x, P = model.update(x, P, z, stds**2)
        for k, kf in enumerate(refs):
            model.filterpy_predict(kf, float(dt[k]))
            kf.update(z[k], R=stds[k] ** 2 * np.eye(2))
            np.testing.assert_allclose(x[k], kf.x.ravel(), rtol=0, atol=1e-12)
            np.testing.assert_allclose(P[k], kf.P, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dt", [0.0, 0.01, 1 / 30, 0.5, 3.0])
def test_process_noise_is_filterpys_continuous_white_noise(dt: float) -> None:
    model = ConstantVelocityModel(accel_noise_mps2=1.7)
    expected = Q_continuous_white_noise(2, dt, 1.7**2, block_size=2, order_by_dim=False)
    np.testing.assert_allclose(model.process_noise(np.array([dt]))[0], expected, atol=1e-15)


def test_prediction_composes_over_irregular_steps() -> None:
    # Continuous white-noise acceleration: predicting a then b equals predicting a + b, so the
    # irregular frame interleaving of several cameras does not change the motion model.
    model = ConstantVelocityModel(1.0)
    x, P = model.initial_state(np.array([[1.0, 2.0]]), np.array([0.01]))
    x[0, 2:] = [0.7, -0.4]
    xa, Pa = model.predict(*model.predict(x, P, np.array([0.013])), np.array([0.087]))
    xb, Pb = model.predict(x, P, np.array([0.1]))
    np.testing.assert_allclose(xa, xb, atol=1e-14)
    np.testing.assert_allclose(Pa, Pb, atol=1e-14)


def test_mahalanobis_and_log_det_match_dense_linear_algebra() -> None:
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 2, 2))
    P_pos = A @ A.transpose(0, 2, 1) * 0.1 + 0.01 * np.eye(2)
    z_pred = rng.normal(size=(5, 2))
    z = rng.normal(size=(4, 2))
    r2 = rng.uniform(0.001, 0.05, size=4)
    d2, log_det = mahalanobis_sq(z_pred, P_pos, z, r2)
    for i in range(5):
        for j in range(4):
            S = P_pos[i] + r2[j] * np.eye(2)
            y = z[j] - z_pred[i]
            assert d2[i, j] == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-10)
            assert log_det[i, j] == pytest.approx(np.log(np.linalg.det(S)), rel=1e-10)


@pytest.mark.parametrize(
    "kwargs", [{"accel_noise_mps2": 0.0}, {"init_velocity_std_mps": -1.0}, {"accel_noise_mps2": math.nan}]
)
def test_model_rejects_bad_parameters(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        ConstantVelocityModel(**kwargs)


# ---------------------------------------------------------------------------------------------- records


def test_gate_is_chi_square_quantile_with_two_dof() -> None:
    assert (
        TrackerConfig().gate_mahalanobis_sq
        == pytest.approx(chi2.ppf(0.99, 2))
        == pytest.approx(9.2103, abs=1e-4)
    )
    assert TrackerConfig(gate_probability=0.95).gate_mahalanobis_sq == pytest.approx(-2 * math.log(0.05))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"gate_probability": 1.0},
        {"gate_probability": 0.0},
        {"lost_after_s": 0.0},
        {"delete_after_s": -1.0},
        {"confirm_window_s": math.inf},
        {"max_detection_delay_s": math.nan},
        {"detections_to_confirm": 0},
        {"detections_to_confirm": 2.5},
        {"max_tracks": 0},
        {"clock_resync_frames": -1},
        {"accel_noise_mps2": "1"},
        {"max_gate_distance_m": 0.0},
        {"min_person_separation_m": -0.1},
    ],
)
def test_config_rejects_bad_values_naming_the_field(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        TrackerConfig(**kwargs)  # type: ignore[arg-type]


def test_detection_validates_shapes_but_keeps_sensor_nans_for_the_tracker() -> None:
    d = Detection([1, 2], "a")  # type: ignore[arg-type]
    assert d.position_xy.dtype == np.float64 and not d.position_xy.flags.writeable
    assert Detection(np.array([math.nan, 0.0]), "a").position_xy.shape == (2,)
    with pytest.raises(ValueError, match="position_xy"):
        Detection(np.zeros(3), "a")
    with pytest.raises(ValueError, match="camera_id"):
        Detection(np.zeros(2), "")
    with pytest.raises(ValueError, match="embedding"):
        Detection(np.zeros(2), "a", embedding=np.zeros((2, 64)))
    with pytest.raises(ValueError, match="embedding"):
        Detection(np.zeros(2), "a", embedding=np.zeros(128, dtype=np.int32))
    with pytest.raises(ValueError, match="position_std_m"):
        Detection(np.zeros(2), "a", position_std_m="0.1")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------- generator


def test_generator_is_deterministic_and_respects_fields_of_view() -> None:
    cams = (CameraFov("a", (0.0, -5.0), math.pi / 2, math.radians(60), 6.0),)
    walker = Walker(1, ((-6.0, 0.0), (6.0, 0.0)), 1.2)
    sc = Scenario((walker,), cams, 8.0, noise_std_m=0.0, miss_probability=0.3, seed=4)
    f1, f2 = sc.frames(), sc.frames()
    assert [(f.stamp_s, f.gt_ids) for f in f1] == [(f.stamp_s, f.gt_ids) for f in f2]
    seen = [f for f in f1 if f.gt_ids]
    # A 60 degree wedge 5 m away spans |x| <= 5 tan 30 = 2.89 m; misses thin the detections out.
    xs = np.array([f.detections[0].position_xy[0] for f in seen])
    assert np.abs(xs).max() <= 5 * math.tan(math.radians(30)) + 1e-9
    in_view = [f for f in f1 if abs(walker.position(f.stamp_s)[0]) < 2.8]  # type: ignore[index]
    assert 0.6 < len(seen) / len(in_view) < 0.8
    assert [f.gt_ids for f in Scenario((walker,), cams, 8.0, miss_probability=0.3, seed=5).frames()] != [
        f.gt_ids for f in f1
    ]


def test_random_walkers_keep_their_separation_and_crossings_meet() -> None:
    assert min_pair_distance(random_walkers(4, seed=3)) >= 0.6
    assert min_pair_distance(crossing_pair(90.0)) < 0.05
    assert min_pair_distance(crossing_pair(45.0, min_separation_m=0.5)) == pytest.approx(0.5, abs=0.03)
    assert min_pair_distance(crossing_pair(180.0, min_separation_m=0.5)) == pytest.approx(0.5, abs=0.03)


# ---------------------------------------------------------------------------------------------- identity


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


def test_tentative_track_converging_on_a_confirmed_one_is_merged_away() -> None:
    tracker = Tracker()
    for k in range(10):
        tracker.update([det(0.0, 0.0)], k / 10, "cam")
    assert tracker.update([det(0.0, 0.0), det(0.6, 0.0)], 1.0, "cam").created == (2,)
    assert tracker.update([det(0.0, 0.0), det(0.48, 0.0)], 1.1, "cam").deleted == ()
    res = tracker.update([det(0.0, 0.0), det(0.36, 0.0)], 1.2, "cam")
    assert (2, 1) in res.associations and res.deleted == (2,) and res.confirmed == ()
    assert tracker.stats.tracks_merged == 1 and tracker.track_ids() == [1]


def test_person_leaving_every_view_and_returning_gets_a_new_track() -> None:
    cfg = TrackerConfig(lost_after_s=1.0, delete_after_s=2.0)
    cam = CameraFov("a", (0.0, -4.0), math.pi / 2, math.radians(70), 6.0)
    # In view (|x| < 2.8 at y = 0) for ~2 s, then out to x = 6 and back: out of view for ~5.7 s.
    walker = Walker(1, ((-1.0, 0.0), (6.5, 0.0), (6.5, 1.0), (0.0, 1.0)), 1.2)
    frames = Scenario((walker,), (cam,), walker.end_s, noise_std_m=0.05, seed=0).frames()
    _, results = run(frames, cfg)
    reps = person_reports(frames, results)
    ids = [t for _, t in reps[1].track_sequence]
    first, second = ids[0], ids[-1]
    assert second > first
    deleted_at = next(r.stamp_s for r in results if first in r.deleted)
    reborn_at = next(r.stamp_s for r in results if second in r.created)
    last_seen = max(t for t, tid in reps[1].track_sequence if tid == first)
    assert deleted_at == pytest.approx(last_seen + 3.0, abs=1 / 30 + 1e-9)
    assert reborn_at > deleted_at
    assert sorted(set(ids)) == [first, second]


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


# ---------------------------------------------------------------------------------------------- lifecycle


LIFECYCLE = TrackerConfig(detections_to_confirm=3, confirm_window_s=1.0, lost_after_s=1.0, delete_after_s=2.0)


def test_lifecycle_transitions_at_exact_times() -> None:
    tracker = Tracker(LIFECYCLE)
    events: dict[float, UpdateResult] = {}
    for t in (0.0, 0.25, 0.5):  # three hits within the window -> confirmed on the third
        events[t] = tracker.update([det(0.0, 0.0)], t, "cam")
    assert events[0.0].created == (1,) and snap(tracker, 1).hits == 3
    assert events[0.25].confirmed == () and events[0.5].confirmed == (1,)
    states = {}
    for k in range(3, 17):  # empty frames every 0.25 s up to t = 4.0
        t = k * 0.25
        events[t] = tracker.update([], t, "cam")
        states[t] = snap(tracker, 1).state if 1 in tracker.track_ids() else TrackState.DELETED
    assert states[1.25] is TrackState.CONFIRMED
    assert events[1.5].lost == (1,) and states[1.5] is TrackState.LOST  # 1.0 s after last detection
    assert states[3.25] is TrackState.LOST and events[3.25].deleted == ()
    assert events[3.5].deleted == (1,) and states[3.5] is TrackState.DELETED  # + 2.0 s lost
    assert tracker.num_tracks == 0 and tracker.stats.tracks_deleted == 1


def test_tentative_track_not_confirmed_in_its_window_is_deleted() -> None:
    tracker = Tracker(LIFECYCLE)
    tracker.update([det(0.0, 0.0)], 0.0, "cam")
    tracker.update([det(0.0, 0.0)], 0.5, "cam")
    assert tracker.update([], 1.0, "cam").deleted == ()
    assert snap(tracker, 1).state is TrackState.TENTATIVE
    res = tracker.update([det(0.0, 0.0)], 1.25, "cam")  # third hit too late: 1.25 s after creation
    assert res.confirmed == () and res.deleted == (1,)
    assert tracker.stats.tracks_confirmed == 0


def test_lost_track_recovers_with_the_same_id() -> None:
    tracker = Tracker(LIFECYCLE)
    for t in (0.0, 0.25, 0.5):
        tracker.update([det(0.0, 0.0)], t, "cam")
    assert tracker.update([], 1.5, "cam").lost == (1,)
    res = tracker.update([det(0.1, 0.0)], 2.0, "cam")
    assert res.recovered == (1,) and res.associations == ((1, 0),) and res.created == ()
    assert snap(tracker, 1).state is TrackState.CONFIRMED


def test_track_timed_out_before_a_frame_does_not_take_its_detection() -> None:
    tracker = Tracker(LIFECYCLE)
    for t in (0.0, 0.25, 0.5):
        tracker.update([det(0.0, 0.0)], t, "cam")
    for k in range(3, 14):  # empty frames up to t = 3.25
        tracker.update([], k * 0.25, "cam")
    assert snap(tracker, 1).state is TrackState.LOST
    res = tracker.update([det(0.0, 0.0)], 3.75, "cam")  # track 1 expired at 3.5, between two frames
    assert res.deleted == (1,) and res.created == (2,) and res.associations == ((2, 0),)


def test_advance_applies_timeouts_without_frames() -> None:
    tracker = Tracker(LIFECYCLE)
    for t in (0.0, 0.25, 0.5):
        tracker.update([det(0.0, 0.0)], t, "cam")
    assert tracker.advance(1.0).lost == ()
    assert tracker.advance(1.5).lost == (1,)
    assert tracker.advance(1.2).status is FrameStatus.ADVANCED and tracker.clock_s == 1.5
    assert tracker.advance(3.5).deleted == (1,)


# ---------------------------------------------------------------------------------------------- time


def _straight_frames(
    stamps: Sequence[float], cams: Sequence[str] | None = None
) -> list[tuple[float, str, list[Detection]]]:
    cams = cams or ["cam"] * len(stamps)
    rng = np.random.default_rng(7)
    out = []
    for t, c in zip(stamps, cams, strict=True):
        xy = np.array([1.0 * t, 0.5 * t]) + rng.normal(scale=0.03, size=2)
        out.append((t, c, [Detection(xy, c, 0.05)]))
    return out


def test_late_frame_within_bound_gives_exactly_the_in_order_state() -> None:
    frames = _straight_frames([0.0, 0.1, 0.2, 0.3, 0.4])
    ordered, shuffled = Tracker(), Tracker()
    for t, c, d in frames:
        ordered.update(d, t, c)
    statuses = [shuffled.update(frames[k][2], frames[k][0], frames[k][1]).status for k in (0, 1, 3, 4, 2)]
    assert statuses[-1] is FrameStatus.APPLIED_LATE and statuses[:-1] == [FrameStatus.APPLIED] * 4
    a, b = snap(ordered, 1), snap(shuffled, 1)
    np.testing.assert_allclose(b.position_xy, a.position_xy, atol=1e-12)
    np.testing.assert_allclose(b.velocity_xy, a.velocity_xy, atol=1e-12)
    np.testing.assert_allclose(b.covariance, a.covariance, atol=1e-12)
    assert b.hits == a.hits == 5 and b.last_seen_s == 0.4 and shuffled.stats.frames_out_of_order == 1


def test_frames_older_than_the_bound_are_rejected_and_counted() -> None:
    tracker = Tracker(TrackerConfig(max_detection_delay_s=0.3))
    for t, c, d in _straight_frames([0.0, 0.5, 1.0]):
        tracker.update(d, t, c)
    before = snap(tracker, 1)
    res = tracker.update([det(0.7, 0.35)], 0.69, "cam")
    assert res.status is FrameStatus.REJECTED_LATE and not res.accepted and res.associations == ()
    after = snap(tracker, 1)
    np.testing.assert_array_equal(after.covariance, before.covariance)
    assert after.hits == before.hits and tracker.stats.frames_rejected_late == 1
    assert tracker.update([det(0.71, 0.355)], 0.71, "cam").status is FrameStatus.APPLIED_LATE
    assert snap(tracker, 1).hits == before.hits + 1


def test_late_detection_older_than_the_track_joins_it() -> None:
    # Camera b's frame (t = 0.10) arrives before camera a's (t = 0.05) of the same person.
    tracker = Tracker()
    assert tracker.update([det(1.0, 1.0, "b")], 0.10, "b").created == (1,)
    res = tracker.update([det(0.95, 1.0, "a")], 0.05, "a")
    assert res.status is FrameStatus.APPLIED_LATE and res.associations == ((1, 0),) and res.created == ()
    s = snap(tracker, 1)
    assert s.created_s == 0.05 and s.last_seen_s == 0.10 and s.hits == 2 and s.cameras == {"a", "b"}
    assert s.velocity_xy[0] > 0.0  # re-filtered in stamp order: 0.95 then 1.0 -> moving +x


def test_multi_camera_out_of_order_stream_equals_stamp_order_processing() -> None:
    cams = (
        CameraFov("a", (-3.0, -5.0), math.radians(70), phase_s=0.0),
        CameraFov("b", (3.0, -5.0), math.radians(110), phase_s=0.011, bias_xy=(0.05, -0.03)),
        CameraFov("c", (0.0, 5.0), math.radians(-90), rate_hz=15.0, phase_s=0.02),
    )
    sc = Scenario(
        random_walkers(3, 1, area_m=6.0), cams, 6.0, 0.05, 0.1, latency_s=0.02, latency_jitter_s=0.15, seed=3
    )
    arrival = sc.frames()
    by_stamp = sorted(arrival, key=lambda f: f.stamp_s)
    assert any(b.stamp_s < a.stamp_s for a, b in itertools.pairwise(arrival))
    t1, r1 = run(arrival)
    t2, _ = run(by_stamp)
    assert t1.stats.frames_out_of_order > 100 and t1.stats.frames_rejected_late == 0
    s1, s2 = t1.snapshots(at_s=6.0), t2.snapshots(at_s=6.0)
    assert [s.track_id for s in s1] == [s.track_id for s in s2] and len(s1) == 3
    for a, b in zip(s1, s2, strict=True):
        np.testing.assert_allclose(a.position_xy, b.position_xy, atol=1e-9)
        np.testing.assert_allclose(a.covariance, b.covariance, atol=1e-9)
        assert a.hits == b.hits
    assert_one_track_per_person(arrival, r1)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(delays=st.lists(st.floats(0.0, 0.25), min_size=30, max_size=30), seed=st.integers(0, 1000))
def test_any_arrival_order_within_the_bound_gives_the_stamp_order_states(
    delays: list[float], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    frames = []
    for k in range(30):  # three cameras interleaved at ~90 Hz overall, two people 4 m apart
        t, cam = k / 90, "abc"[k % 3]
        people = [
            np.array([0.0, 0.0]) + t * np.array([1.0, 0.3]),
            np.array([4.0, 0.0]) + t * np.array([-0.5, 0.8]),
        ]
        dets = [
            Detection(p + rng.normal(scale=0.03, size=2), cam, 0.05) for p in people if rng.random() > 0.2
        ]
        frames.append((t, cam, dets))
    arrival = [frames[k] for k in sorted(range(30), key=lambda k: frames[k][0] + delays[k])]
    ordered, shuffled = Tracker(), Tracker()
    for t, cam, dets in frames:
        ordered.update(dets, t, cam)
    results = [shuffled.update(dets, t, cam) for t, cam, dets in arrival]
    assert all(r.accepted for r in results)
    a = sorted(ordered.snapshots(at_s=0.5), key=lambda s: s.position_xy[0])
    b = sorted(shuffled.snapshots(at_s=0.5), key=lambda s: s.position_xy[0])
    assert len(a) == len(b) == 2
    for sa, sb in zip(a, b, strict=True):
        np.testing.assert_allclose(sb.position_xy, sa.position_xy, atol=1e-9)
        np.testing.assert_allclose(sb.covariance, sa.covariance, atol=1e-9)
        assert (sb.hits, sb.state, sb.created_s, sb.last_seen_s) == (
            sa.hits,
            sa.state,
            sa.created_s,
            sa.last_seen_s,
        )


def test_future_stamps_are_rejected_until_a_run_of_them_resyncs_the_clock() -> None:
    tracker = Tracker(TrackerConfig(max_future_stamp_s=1.0, clock_resync_frames=3))
    for t in (0.0, 0.1, 0.2):
        tracker.update([det(0.0, 0.0)], t, "cam")
    res = tracker.update([det(0.0, 0.0, "bad_clock")], 50.0, "bad_clock")
    assert res.status is FrameStatus.REJECTED_FUTURE and tracker.clock_s == 0.2
    assert tracker.update([det(0.0, 0.0)], 0.3, "cam").status is FrameStatus.APPLIED  # run broken
    assert tracker.update([], 60.0, "x").status is FrameStatus.REJECTED_FUTURE
    assert tracker.update([], 60.1, "x").status is FrameStatus.REJECTED_FUTURE
    res = tracker.update([det(5.0, 5.0, "x")], 60.2, "x")  # third in a row: cameras restarted after idling
    assert res.status is FrameStatus.APPLIED and res.clock_resync and tracker.clock_s == 60.2
    assert res.deleted == (1,) and res.created == (2,)  # the old track timed out in the gap
    assert tracker.stats.frames_rejected_future == 3 and tracker.stats.clock_resyncs == 1


def test_backward_clock_jump_resets_after_a_run_of_late_frames() -> None:
    tracker = Tracker(TrackerConfig(clock_resync_frames=2))
    for t in (100.0, 100.1):
        tracker.update([det(0.0, 0.0)], t, "cam")
    assert tracker.update([det(0.0, 0.0)], 3.0, "cam").status is FrameStatus.REJECTED_LATE
    res = tracker.update([det(0.0, 0.0)], 3.1, "cam")  # bag replay looped: start afresh
    assert res.clock_resync and res.deleted == (1,) and res.created == (2,) and tracker.clock_s == 3.1


# ---------------------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("bad", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan)])
def test_nonfinite_detections_are_rejected_and_counted(bad: tuple[float, float]) -> None:
    tracker = Tracker()
    res = tracker.update([det(1.0, 1.0), det(*bad), det(3.0, 3.0)], 0.0, "cam")
    assert res.rejected_detections == (1,)
    assert sorted(d for _, d in res.associations) == [0, 2] and len(res.created) == 2
    assert tracker.stats.detections_rejected_nonfinite == 1 and tracker.stats.detections_received == 3
    assert all(np.isfinite(s.position_xy).all() for s in tracker.snapshots())


@pytest.mark.parametrize("std", [0.0, -0.1, math.nan, math.inf])
def test_bad_measurement_std_is_rejected_and_counted(std: float) -> None:
    tracker = Tracker()
    res = tracker.update([det(1.0, 1.0, std=std)], 0.0, "cam")
    assert (
        res.rejected_detections == (0,)
        and res.created == ()
        and tracker.stats.detections_rejected_bad_std == 1
    )


def test_programming_errors_raise_value_error() -> None:
    tracker = Tracker()
    with pytest.raises(ValueError, match="camera_id"):
        tracker.update([det(0.0, 0.0, "a")], 0.0, "b")
    with pytest.raises(ValueError, match="stamp_s"):
        tracker.update([], math.nan, "a")
    with pytest.raises(ValueError, match=r"detections\[0\]"):
        tracker.update([np.zeros(2)], 0.0, "a")  # type: ignore[list-item]
    with pytest.raises(ValueError, match="sequence"):
        tracker.update(det(0.0, 0.0, "a"), 0.0, "a")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="config"):
        Tracker({"lost_after_s": 1.0})  # type: ignore[arg-type]
    assert tracker.stats.frames_processed == 0


# ---------------------------------------------------------------------------------------------- outputs


def test_results_and_snapshots_carry_faces_for_the_identity_layer() -> None:
    tracker = Tracker()
    e1, e2 = np.full(128, 0.1, dtype=np.float32), np.full(128, -0.1, dtype=np.float32)
    r0 = tracker.update([det(0.0, 0.0, embedding=e1, height_m=1.75), det(3.0, 0.0)], 0.0, "cam")
    assert r0.associations == ((1, 0), (2, 1)) and r0.created == (1, 2)
    r1 = tracker.update([det(3.0, 0.05), det(0.02, 0.0, embedding=e2)], 0.1, "cam")
    assert r1.track_of_detection() == {0: 2, 1: 1}
    s1 = snap(tracker, 1)
    assert len(s1.associated) == 1 and s1.associated[0][0] == 1 and s1.associated[0][1] is e2
    assert s1.height_m == 1.75 and s1.cameras == {"cam"} and s1.stamp_s == 0.1
    assert snap(tracker, 2).associated[0][1] is None
    tracker.update([], 0.2, "cam")
    assert snap(tracker, 1).associated == ()
    s = tracker.snapshots(at_s=1.0)[0]
    assert s.stamp_s == 1.0 and s.covariance.shape == (4, 4) and not s.position_xy.flags.writeable


def test_duplicate_detections_of_one_person_start_one_track() -> None:
    tracker = Tracker()
    res = tracker.update([det(1.0, 1.0), det(1.15, 1.05), det(4.0, 4.0)], 0.0, "cam")
    assert res.created == (1, 2) and res.suppressed_detections == (1,)
    assert tracker.stats.detections_suppressed_near_track == 1


def test_track_limit_drops_and_counts_extra_detections() -> None:
    tracker = Tracker(TrackerConfig(max_tracks=2))
    res = tracker.update([det(0.0, 0.0), det(2.0, 0.0), det(4.0, 0.0)], 0.0, "cam")
    assert res.created == (1, 2) and res.rejected_detections == (2,) and tracker.num_tracks == 2
    assert tracker.stats.detections_dropped_track_limit == 1


def test_reset_deletes_everything_and_ids_keep_increasing() -> None:
    tracker = Tracker()
    tracker.update([det(0.0, 0.0), det(2.0, 0.0)], 0.0, "cam")
    assert tracker.reset() == (1, 2) and tracker.num_tracks == 0 and tracker.clock_s is None
    assert tracker.update([det(0.0, 0.0)], 0.0, "cam").created == (3,)
