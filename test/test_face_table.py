"""Tests of the face identity layer: Bayesian table, Sinkhorn, Algorithm 1, threshold baseline."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import optimize, stats

from face_reid_master.identity.face_table import (
    FaceIdentityManager,
    IdentityEvent,
    IdentityEventKind,
    LearnedFace,
    ThresholdIdentityManager,
    make_identity_manager,
    min_distances_to_faces,
    select_diverse_subset,
    sinkhorn_with_slack,
)
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal

REPO_ROOT = Path(__file__).resolve().parents[1]
FACES_DIR = REPO_ROOT / "test" / "data" / "faces"
YUNET_PATH = REPO_ROOT / "models" / "face_detection_yunet_2023mar.onnx"
DIM = 128

ASSIGNED = IdentityEventKind.ASSIGNED_KNOWN
NEW = IdentityEventKind.NEW_FACE
RELEASED = IdentityEventKind.RELEASED

# Normal likelihoods N_p = N(0, s^2), N_n = N(1, s^2) with s^2 = 1 / (2 ln 2):
# log N_p(d)/N_n(d) = ((d - 1)^2 - d^2) / (2 s^2) = (1 - 2d) ln 2, i.e. N_p/N_n = 2^(1 - 2d):
# d = 0 -> 2, d = 0.5 -> 1, d = 1 -> 1/2.
SIGMA = 1.0 / math.sqrt(2.0 * math.log(2.0))
SIMPLE = LikelihoodModel(SkewNormal(0.0, 0.0, SIGMA), SkewNormal(0.0, 1.0, SIGMA))


def _e(i: int, scale: float = 1.0) -> np.ndarray:
    v = np.zeros(DIM, dtype=np.float32)
    v[i] = scale
    return v


def _kinds(events: list[IdentityEvent]) -> list[tuple[IdentityEventKind, int, int]]:
    return [(e.kind, e.track_id, e.face_id) for e in events]


# ------------------------------------------------------------------------------------------------
# Hand-computed Bayesian update + Sinkhorn (2 tracks x 2 faces + slack)
# ------------------------------------------------------------------------------------------------
def _two_by_two(c: float, iterations: int, solver: str = "sinkhorn") -> FaceIdentityManager:
    """Faces 1 (feature 0) and 2 (feature e_0), track A at 0, track B at e_0 / 2, one observation each."""
    m = FaceIdentityManager(
        SIMPLE.with_new_person_scale(c),
        prior_probability=0.1,
        min_observations=1000,  # no decisions: inspect the table
        sinkhorn_max_iterations=iterations,
        sinkhorn_tolerance=1e-13,
        sinkhorn_solver=solver,
    )
    m.import_faces([LearnedFace(1, np.zeros((1, DIM), np.float32)), LearnedFace(2, _e(0)[None])])
    m.add_observations(100, np.zeros((1, DIM), np.float32), 0.0)  # d = 0 to face 1, 1 to face 2
    m.add_observations(200, _e(0, 0.5)[None], 0.0)  # d = 0.5 to both faces
    assert m.step(0.0) == []
    return m


F = Fraction
# By hand.  Prior table (row 0 = "not tracked", column 0 = "new person"; cell (0,0) unused):
#   row0 [0, .1, .1]   rowA [.1, .1, .1]   rowB [.1, .1, .1]
# Likelihood ratios (column 0: c; column j: N_p/N_n = 2^(1-2d)):  A x [c, 2, 1/2],  B x [c, 1, 1].
# c = 1:  A = [.1, .2, .05] (sum .35) -> [2/7, 4/7, 1/7];  B = [.1,.1,.1] -> [1/3, 1/3, 1/3]
#   column 1: .1 + 4/7 + 1/3 = 211/210 -> row0 21/211, A 120/211, B 70/211
#   column 2: .1 + 1/7 + 1/3 = 121/210 -> row0 21/121, A 30/121,  B 70/121
# c = 2:  A = [.2, .2, .05] (sum .45) -> [4/9, 4/9, 1/9];  B = [.2, .1, .1] -> [1/2, 1/4, 1/4]
#   column 1: .1 + 4/9 + 1/4 = 143/180 -> row0 18/143, A 80/143, B 45/143
#   column 2: .1 + 1/9 + 1/4 = 83/180  -> row0 18/83,  A 20/83,  B 45/83
HAND_ONE_ITERATION = {
    1.0: [[0, F(21, 211), F(21, 121)], [F(2, 7), F(120, 211), F(30, 121)], [F(1, 3), F(70, 211), F(70, 121)]],
    2.0: [[0, F(18, 143), F(18, 83)], [F(4, 9), F(80, 143), F(20, 83)], [F(1, 2), F(45, 143), F(45, 83)]],
}


@pytest.mark.parametrize("c", [1.0, 2.0])
def test_one_bayes_update_and_sinkhorn_pass_match_hand_computation(c: float) -> None:
    m = _two_by_two(c, iterations=1)
    table, rows, cols = m.posterior_table()
    assert rows == [100, 200] and cols == [1, 2]
    expected = np.array([[float(x) for x in row] for row in HAND_ONE_ITERATION[c]])
    np.testing.assert_allclose(table, expected, rtol=1e-6, atol=1e-9)  # float32 distances
    assert m.posterior_of(100) == pytest.approx({0: expected[1, 0], 1: expected[1, 1], 2: expected[1, 2]})
    assert m.confidence_of(100) == pytest.approx(expected[1, 1])
    np.testing.assert_array_equal(m.observation_counts(), [[0, 0, 0], [1, 1, 1], [1, 1, 1]])


@pytest.mark.parametrize("solver", ["sinkhorn", "newton"])
def test_converged_table_is_the_scaled_fixed_point_found_independently(solver: str) -> None:
    m = _two_by_two(1.0, iterations=10_000, solver=solver)
    assert m.is_normalised
    p, _, _ = m.posterior_table()
    k = np.array([[0.0, 0.1, 0.1], [0.1, 0.2, 0.05], [0.1, 0.1, 0.1]])  # prior x likelihood (see above)

    # independent solution of P = diag(1, a1, a2) K diag(1, b1, b2) with rows/columns 1..2 summing to 1
    def equations(x: np.ndarray) -> list[float]:
        a = np.array([1.0, x[0], x[1]])
        b = np.array([1.0, x[2], x[3]])
        q = a[:, None] * k * b[None, :]
        return [q[1].sum() - 1, q[2].sum() - 1, q[:, 1].sum() - 1, q[:, 2].sum() - 1]

    sol = optimize.fsolve(equations, np.ones(4), xtol=1e-14)
    a = np.array([1.0, sol[0], sol[1]])
    b = np.array([1.0, sol[2], sol[3]])
    expected = a[:, None] * k * b[None, :]
    np.testing.assert_allclose(p, expected, rtol=1e-5, atol=1e-9)
    # cross-ratios of a diagonal scaling are those of K: (A1 * B2) / (A2 * B1) = (.2 * .1) / (.05 * .1) = 4
    assert p[1, 1] * p[2, 2] / (p[1, 2] * p[2, 1]) == pytest.approx(4.0, rel=1e-5)
    assert p[0, 1] * p[1, 2] / (p[0, 2] * p[1, 1]) == pytest.approx(0.25, rel=1e-5)


def test_ratio_form_equals_the_papers_product_of_eq5_over_faces() -> None:
    """Eq. 5 applied for every learned face k (OpenPTrack): column j gets N_p(d_ij) prod_{k!=j} N_n(d_ik),
    column 0 gets c N_n(d_ik) per face; with c = 1 this must give the same posterior as the ratio form."""
    rng = np.random.default_rng(7)
    faces = [rng.normal(0, 0.06, (3, DIM)).astype(np.float32) for _ in range(3)]
    obs = {
        10: rng.normal(0, 0.06, (2, DIM)).astype(np.float32),
        20: rng.normal(0, 0.06, (1, DIM)).astype(np.float32),
    }
    m = FaceIdentityManager(
        SIMPLE, min_observations=1000, sinkhorn_max_iterations=5000, sinkhorn_tolerance=1e-13
    )
    m.import_faces([LearnedFace(j + 1, f) for j, f in enumerate(faces)])
    for tid, o in obs.items():
        m.add_observations(tid, o, 0.0)
    m.step(0.0)
    got, _, _ = m.posterior_table()

    npdf = stats.norm(0.0, SIGMA).pdf
    ndf = stats.norm(1.0, SIGMA).pdf
    table = np.full((3, 4), 0.1)
    table[0, 0] = 0.0
    for row, tid in enumerate((10, 20), start=1):
        d = min_distances_to_faces(obs[tid], faces)  # float64 reference, (n_obs, 3)
        for t in range(d.shape[0]):
            for k in range(3):
                lik = np.full(4, ndf(d[t, k]))  # N_n in every column (column 0: c = 1)
                lik[k + 1] = npdf(d[t, k])
                table[row] *= lik
    for _ in range(5000):  # plain Sinkhorn: rows 1..2 then columns 1..3
        table[1:] /= table[1:].sum(axis=1, keepdims=True)
        table[:, 1:] /= table[:, 1:].sum(axis=0, keepdims=True)
    np.testing.assert_allclose(got, np.clip(table, 1e-3, 1 - 1e-3) * (table > 0), rtol=1e-4, atol=1e-7)


# ------------------------------------------------------------------------------------------------
# Sinkhorn
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("solver", ["sinkhorn", "newton"])
@pytest.mark.parametrize("shape", [(2, 2), (3, 5), (6, 2), (11, 41), (51, 301)])
def test_sinkhorn_normalises_rows_and_columns_of_random_tables(shape: tuple[int, int], solver: str) -> None:
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    k = rng.uniform(1e-3, 1.0, shape) ** 3
    k[0, 0] = 0.25
    res = sinkhorn_with_slack(k, tolerance=1e-9, max_iterations=10_000, solver=solver)
    assert res.converged and res.max_row_error < 1e-9
    if solver == "newton":
        assert res.iterations < 30
        plain = sinkhorn_with_slack(k, tolerance=1e-12, max_iterations=100_000, solver="sinkhorn")
        np.testing.assert_allclose(res.table, plain.table, atol=1e-8)  # the same fixed point
    np.testing.assert_allclose(res.table[1:].sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(res.table[:, 1:].sum(axis=0), 1.0, atol=1e-12)
    assert res.table[0, 0] == 0.25  # untouched
    assert np.all(res.table >= 0)


def test_sinkhorn_degenerate_sizes() -> None:
    only_rows = sinkhorn_with_slack([[0.0], [0.3], [0.7]])
    np.testing.assert_allclose(only_rows.table[1:, 0], 1.0)
    only_cols = sinkhorn_with_slack([[0.0, 0.2, 0.5]])
    np.testing.assert_allclose(only_cols.table[0, 1:], 1.0)


def test_sinkhorn_reports_non_convergence_within_iteration_budget() -> None:
    k = [[0.0, 0.001], [0.001, 0.99], [0.999, 0.001]]  # nearly degenerate: the alternations crawl
    res = sinkhorn_with_slack(k, tolerance=1e-12, max_iterations=3, solver="sinkhorn")
    assert not res.converged and res.iterations == 3 and res.max_row_error > 1e-12
    fast = sinkhorn_with_slack(k, tolerance=1e-12, max_iterations=50, solver="newton")
    assert fast.converged and fast.iterations < 15
    slow = sinkhorn_with_slack(k, tolerance=1e-12, max_iterations=100_000, solver="sinkhorn")
    assert slow.converged and slow.iterations > 1000
    np.testing.assert_allclose(fast.table, slow.table, atol=1e-9)
    with pytest.raises(ValueError):
        sinkhorn_with_slack(k, solver="magic")


@pytest.mark.parametrize(
    "bad", [[[0.0, -0.1], [0.2, 0.3]], [[0.0, math.nan], [0.2, 0.3]], [[0.0, 0.1], [0.0, 0.0]], [1.0, 2.0]]
)
def test_sinkhorn_rejects_bad_tables(bad: list) -> None:
    with pytest.raises(ValueError):
        sinkhorn_with_slack(bad)


# ------------------------------------------------------------------------------------------------
# Algorithm 1 transitions (hand-built embeddings with dlib-like geometry)
# ------------------------------------------------------------------------------------------------
CENTRES = [_e(i, 0.7) for i in range(8)]  # different people ~0.99 apart
NOISE = 0.3 / math.sqrt(2 * DIM)  # same person ~0.3 apart


def _person(p: int, n: int, rng: np.random.Generator) -> np.ndarray:
    return (CENTRES[p] + rng.normal(0.0, NOISE, (n, DIM))).astype(np.float32)


def _manager_with_faces(n_faces: int, rng: np.random.Generator, **kw: object) -> FaceIdentityManager:
    m = FaceIdentityManager(**kw)  # type: ignore[arg-type]
    m.import_faces([LearnedFace(j + 1, _person(j, 5, rng)) for j in range(n_faces)])
    return m


def _feed(m: FaceIdentityManager, track: int, person: int, rng: np.random.Generator, t: float) -> list:
    m.add_observations(track, _person(person, 1, rng), t)
    return m.step(t)


def test_known_person_is_assigned_after_min_observations() -> None:
    rng = np.random.default_rng(1)
    m = _manager_with_faces(3, rng, min_observations=3)
    assert _feed(m, 10, 1, rng, 0.0) == []
    assert m.posterior_of(10)[2] > 0.95  # already confident ...
    assert _feed(m, 10, 1, rng, 0.1) == []  # ... but only 2 observations
    assert m.face_id_of(10) is None
    events = _feed(m, 10, 1, rng, 0.2)
    assert _kinds(events) == [(ASSIGNED, 10, 2)]
    assert events[0].confidence > 0.95 and events[0].stamp_s == 0.2
    assert m.face_id_of(10) == 2 and m.confidence_of(10) == events[0].confidence
    assert m.available_face_ids() == [1, 3]
    assert len(m.face_features(2)) == 5 + 3  # the track's observations joined the face
    assert m.posterior_of(10) == {}


def test_unknown_person_gets_a_new_face_id() -> None:
    rng = np.random.default_rng(2)
    m = _manager_with_faces(3, rng, min_observations=3)
    events = []
    for i in range(3):
        events += _feed(m, 10, 5, rng, 0.1 * i)
    assert _kinds(events) == [(NEW, 10, 4)]
    assert m.face_ids() == [1, 2, 3, 4] and m.available_face_ids() == [1, 2, 3]
    assert len(m.face_features(4)) == 3


def test_first_person_ever_becomes_face_1() -> None:
    rng = np.random.default_rng(3)
    m = FaceIdentityManager(min_observations=2)
    assert _feed(m, 7, 0, rng, 0.0) == []
    assert m.posterior_of(7) == {0: pytest.approx(1 - 1e-3)}
    assert _kinds(_feed(m, 7, 0, rng, 0.1)) == [(NEW, 7, 1)]


def test_track_death_releases_the_face_which_is_assignable_again() -> None:
    rng = np.random.default_rng(4)
    m = _manager_with_faces(3, rng, min_observations=3)
    for i in range(3):
        _feed(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2
    m.track_deleted(10, 1.0)
    events = m.step(1.0)
    assert _kinds(events) == [(RELEASED, 10, 2)]
    assert m.face_id_of(10) is None and m.available_face_ids() == [1, 3, 2]
    events = []
    for i in range(3):
        events += _feed(m, 11, 1, rng, 2.0 + 0.1 * i)
    assert _kinds(events) == [(ASSIGNED, 11, 2)]


def test_face_of_a_live_track_is_not_assignable_to_a_simultaneous_track() -> None:
    rng = np.random.default_rng(5)
    m = _manager_with_faces(3, rng, min_observations=3)
    for i in range(3):
        _feed(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2
    events = []
    for i in range(4):  # the same person seen by a second, simultaneous track (e.g. a tracker split)
        events += _feed(m, 11, 1, rng, 1.0 + 0.1 * i)
        assert 2 not in m.posterior_of(11)
    assert m.face_id_of(11) != 2 and (ASSIGNED, 11, 2) not in _kinds(events)
    assert m.assigned_tracks()[10] == 2


def test_assigned_track_keeps_extending_its_face_within_the_bound() -> None:
    rng = np.random.default_rng(6)
    m = _manager_with_faces(2, rng, min_observations=1, max_features_per_face=8)
    _feed(m, 10, 0, rng, 0.0)
    assert m.face_id_of(10) == 1 and len(m.face_features(1)) == 6
    m.add_observations(10, _person(0, 2, rng), 0.1)
    m.step(0.1)
    assert len(m.face_features(1)) == 8
    for i in range(10):
        _feed(m, 10, 0, rng, 0.2 + 0.1 * i)
    assert len(m.face_features(1)) == 8
    faces = {f.face_id: f for f in m.export_faces()}
    assert faces[1].n_observations == 1 + 2 + 10  # the import said 0 observations
    assert faces[1].last_seen_s == pytest.approx(1.1)


def test_several_observations_and_calls_in_one_step_are_pooled() -> None:
    rng = np.random.default_rng(7)
    m = _manager_with_faces(3, rng, min_observations=3)
    m.add_observations(10, _person(2, 2, rng), 0.0)
    m.add_observations(10, _person(2, 1, rng), 0.0)
    assert _kinds(m.step(0.0)) == [(ASSIGNED, 10, 3)]


def test_decided_and_deleted_in_the_same_step_gives_new_then_released() -> None:
    rng = np.random.default_rng(8)
    m = FaceIdentityManager(min_observations=2)
    m.add_observations(10, _person(0, 2, rng), 0.0)
    m.track_deleted(10, 0.0)
    assert _kinds(m.step(0.0)) == [(NEW, 10, 1), (RELEASED, 10, 1)]
    assert m.available_face_ids() == [1]


def test_late_observations_of_deleted_tracks_are_ignored() -> None:
    rng = np.random.default_rng(9)
    m = FaceIdentityManager(min_observations=2)
    m.add_observations(10, _person(0, 1, rng), 0.0)
    m.track_deleted(10, 0.1)
    assert m.step(0.1) == []
    assert m.add_observations(10, _person(0, 1, rng), 0.2) is False
    assert m.step(0.2) == [] and m.live_track_ids() == []
    assert m.stats.observations_ignored_dead_track == 1
    assert m.posterior_table()[1] == []


def test_sync_alive_tracks_deletes_missing_tracks() -> None:
    rng = np.random.default_rng(10)
    m = FaceIdentityManager(min_observations=1)
    _feed(m, 1, 0, rng, 0.0)
    _feed(m, 2, 1, rng, 0.0)
    m.sync_alive_tracks([2], 1.0)
    assert _kinds(m.step(1.0)) == [(RELEASED, 1, 1)]
    assert m.live_track_ids() == [2]


def test_new_person_scale_c_biases_towards_new_faces() -> None:
    rng = np.random.default_rng(11)
    obs = (CENTRES[1] + CENTRES[2]) / 2 + rng.normal(0, NOISE, (1, DIM)).astype(np.float32)  # ambiguous
    posts = []
    for c in (1.0, 100.0):
        m = _manager_with_faces(
            3,
            np.random.default_rng(12),
            likelihood=LikelihoodModel.default().with_new_person_scale(c),
            min_observations=100,
        )
        m.add_observations(10, obs, 0.0)
        m.step(0.0)
        posts.append(m.posterior_of(10)[0])
    assert posts[1] > posts[0]


def test_threshold_baseline_decides_by_majority_after_n_votes() -> None:
    rng = np.random.default_rng(13)
    m = ThresholdIdentityManager(distance_threshold=0.6, n_votes=5)
    m.import_faces([LearnedFace(j + 1, _person(j, 5, rng)) for j in range(3)])
    far = [_person(6, 1, rng), _person(7, 1, rng)]  # 2 votes "new"
    near = [_person(1, 1, rng) for _ in range(3)]  # 3 votes for face 2
    for i, o in enumerate([near[0], far[0], near[1], far[1]]):
        m.add_observations(10, o, 0.1 * i)
        assert m.step(0.1 * i) == []
    assert m.confidence_of(10) == pytest.approx(0.5)
    m.add_observations(10, near[2], 0.5)
    events = m.step(0.5)
    assert _kinds(events) == [(ASSIGNED, 10, 2)] and events[0].confidence == pytest.approx(0.6)
    # a stranger: all votes "new"
    for i in range(5):
        m.add_observations(11, _person(5, 1, rng), 1.0 + i)
        events = m.step(1.0 + i)
    assert _kinds(events) == [(NEW, 11, 4)]


def test_threshold_baseline_tie_goes_to_new_face() -> None:
    rng = np.random.default_rng(14)
    m = make_identity_manager("threshold", distance_threshold=0.6, n_votes=4)
    m.import_faces([LearnedFace(1, _person(0, 5, rng))])
    m.add_observations(3, np.concatenate([_person(0, 2, rng), _person(4, 2, rng)]), 0.0)
    assert _kinds(m.step(0.0)) == [(NEW, 3, 2)]


# ------------------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "emb",
    [
        np.zeros((1, 127), np.float32),
        np.zeros(128, np.float32),
        np.full((2, 128), np.nan, np.float32),
        np.full((1, 128), np.inf),
        np.zeros((1, 128), bool),
        np.array([["a"] * 128]),
    ],
)
def test_bad_embeddings_raise_value_error(emb: np.ndarray) -> None:
    m = FaceIdentityManager()
    with pytest.raises(ValueError):
        m.add_observations(1, emb, 0.0)
    assert m.live_track_ids() == []


@pytest.mark.parametrize("track_id", [1.5, "3", True, None])
def test_bad_track_ids_raise(track_id: object) -> None:
    with pytest.raises(ValueError):
        FaceIdentityManager().add_observations(track_id, np.zeros((1, DIM)), 0.0)  # type: ignore[arg-type]


def test_bad_stamp_raises() -> None:
    with pytest.raises(ValueError):
        FaceIdentityManager().step(math.nan)


@pytest.mark.parametrize(
    "kw",
    [
        {"prior_probability": 0.0},
        {"prior_probability": 1.0},
        {"posterior_threshold": 0.5},
        {"posterior_threshold": 0.9995},
        {"min_observations": 0},
        {"clamp_probability": 0.6},
        {"sinkhorn_tolerance": 0.0},
        {"sinkhorn_max_iterations": 0},
        {"max_abs_log_likelihood_ratio": -1.0},
        {"max_features_per_face": 0},
        {"embedding_dim": 0},
        {"shortlist_faces": 0},
        {"likelihood": "default"},
        {"min_observations": 2.5},
    ],
)
def test_bad_constructor_arguments_raise(kw: dict) -> None:
    with pytest.raises(ValueError):
        FaceIdentityManager(**kw)


def test_factory() -> None:
    assert isinstance(make_identity_manager("bayes"), FaceIdentityManager)
    assert isinstance(make_identity_manager("threshold", n_votes=3), ThresholdIdentityManager)
    with pytest.raises(ValueError):
        make_identity_manager("svm")
    with pytest.raises(ValueError):
        ThresholdIdentityManager(distance_threshold=0.0)


# ------------------------------------------------------------------------------------------------
# Persistence hooks
# ------------------------------------------------------------------------------------------------
def test_export_import_roundtrip_continues_face_ids() -> None:
    rng = np.random.default_rng(15)
    m = FaceIdentityManager(min_observations=2)
    for t in range(2):
        _feed(m, 1, 0, rng, t)
        _feed(m, 2, 1, rng, t)
    m.set_face_name(2, "Ada")
    exported = m.export_faces()
    assert [f.face_id for f in exported] == [1, 2] and exported[1].name == "Ada"
    fresh = FaceIdentityManager(min_observations=2)
    fresh.import_faces(exported)
    assert fresh.face_ids() == [1, 2] and fresh.face_name(2) == "Ada"
    np.testing.assert_array_equal(fresh.face_features(1), m.face_features(1))
    events = []
    for t in range(3):
        events += _feed(fresh, 9, 1, rng, t)  # person 1 again: known
        events += _feed(fresh, 8, 3, rng, t)  # someone new: id 3
    assert sorted(_kinds(events)) == sorted([(ASSIGNED, 9, 2), (NEW, 8, 3)])
    with pytest.raises(ValueError, match="already exists"):
        fresh.import_faces([LearnedFace(1, np.zeros((1, DIM), np.float32))])
    with pytest.raises(ValueError, match="dim"):
        fresh.import_faces([LearnedFace(7, np.zeros((1, 64), np.float32))])
    with pytest.raises(ValueError):
        LearnedFace(0, np.zeros((1, DIM)))
    with pytest.raises(ValueError):
        LearnedFace(3, np.full((1, DIM), np.nan))


# ------------------------------------------------------------------------------------------------
# Bounded, diverse feature sets
# ------------------------------------------------------------------------------------------------
def _min_pairwise(x: np.ndarray) -> float:
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return float(d.min())


def test_diverse_subset_beats_fifo_on_a_clustered_set() -> None:
    rng = np.random.default_rng(16)
    # 5 views of a face, 30 near-duplicate frames each, seen one view after the other
    views = rng.normal(0, 0.05, (5, DIM))
    feats = np.concatenate([v + rng.normal(0, 0.003, (30, DIM)) for v in views]).astype(np.float32)
    keep = select_diverse_subset(feats, 10)
    assert len(keep) == 10 and np.all(np.diff(keep) > 0)
    fifo = feats[-10:]
    assert _min_pairwise(feats[keep]) >= _min_pairwise(fifo)
    assert len({int(i) // 30 for i in keep}) == 5  # every view kept; FIFO keeps only the last one
    # the manager's incremental bank keeps the same kind of set
    m = FaceIdentityManager(max_features_per_face=10, min_observations=1)
    for i in range(0, len(feats), 3):
        m.add_observations(1, feats[i : i + 3], float(i))
        m.step(float(i))
    stored = m.face_features(1)
    assert len(stored) == 10 and _min_pairwise(stored) >= _min_pairwise(fifo)
    assert len({int(np.argmin(((views - s) ** 2).sum(1))) for s in stored}) == 5


def test_incremental_insertion_matches_greedy_selection() -> None:
    rng = np.random.default_rng(17)
    m = FaceIdentityManager(max_features_per_face=6, min_observations=1, embedding_dim=8)
    reference = np.zeros((0, 8), np.float32)
    for i in range(40):
        x = rng.normal(size=(1 + i % 2, 8)).astype(np.float32)
        m.add_observations(1, x, float(i))
        m.step(float(i))
        allf = np.concatenate([reference, x])
        reference = allf[select_diverse_subset(allf, 6)]
        got = m.face_features(1)
        assert sorted(map(tuple, got.round(5))) == sorted(map(tuple, reference.round(5)))


def test_batched_insertion_for_several_identified_tracks_matches_greedy_selection() -> None:
    rng = np.random.default_rng(23)
    m = FaceIdentityManager(max_features_per_face=5, min_observations=1, embedding_dim=8)
    history: dict[int, np.ndarray] = {}
    for step in range(30):
        for tid in (1, 2, 3, 4):
            x = rng.normal(size=(1, 8)).astype(np.float32)
            m.add_observations(tid, x, float(step))
            history[tid] = np.concatenate([history.get(tid, np.zeros((0, 8), np.float32)), x])
            if step > 3:
                ref = history[tid]
                history[tid] = ref[select_diverse_subset(ref, 5)]
        m.step(float(step))
    assert sorted(m.assigned_tracks()) == [1, 2, 3, 4]
    for tid, fid in m.assigned_tracks().items():
        expected = history[tid][select_diverse_subset(history[tid], 5)]
        got = m.face_features(fid)
        assert sorted(map(tuple, got.round(5))) == sorted(map(tuple, expected.round(5)))


# ------------------------------------------------------------------------------------------------
# Distances (eq. 4)
# ------------------------------------------------------------------------------------------------
def test_bank_distances_match_float64_reference_in_exact_and_shortlist_modes() -> None:
    rng = np.random.default_rng(18)
    faces = [
        (c + rng.normal(0, 0.02, (int(rng.integers(1, 9)), DIM))).astype(np.float32)
        for c in rng.normal(0, 0.06, (60, DIM))
    ]
    obs = np.concatenate([faces[3][:1], faces[40][:1], rng.normal(0, 0.06, (1, DIM))]).astype(np.float32)
    ref = min_distances_to_faces(obs, faces)
    exact = FaceIdentityManager()
    exact.import_faces(LearnedFace(i + 1, f) for i, f in enumerate(faces))
    # float32 ||a||^2 + ||b||^2 - 2ab: squared distances exact to ~1e-6 (d = 0 reads as ~3e-4)
    np.testing.assert_allclose(exact._available_distances(obs) ** 2, ref**2, atol=2e-6)
    short = FaceIdentityManager(exact_search_max_features=10, shortlist_faces=8)
    short.import_faces(LearnedFace(i + 1, f) for i, f in enumerate(faces))
    d = short._available_distances(obs)
    assert short.stats.shortlist_searches == 1
    assert np.all(np.isfinite(d).sum(axis=1) == 8)
    np.testing.assert_allclose(d[np.isfinite(d)] ** 2, ref[np.isfinite(d)] ** 2, atol=2e-6)
    assert np.all(np.argmin(d, axis=1) == np.argmin(ref, axis=1))  # the nearest face is always shortlisted


def test_shortlist_mode_still_identifies_people() -> None:
    rng = np.random.default_rng(19)
    m = _manager_with_faces(8, rng, exact_search_max_features=10, shortlist_faces=2, min_observations=3)
    events = []
    for i in range(3):
        events += _feed(m, 1, 6, rng, i)
    assert _kinds(events) == [(ASSIGNED, 1, 7)] and m.stats.shortlist_searches > 0


# ------------------------------------------------------------------------------------------------
# Property test: random operation sequences keep the invariants
# ------------------------------------------------------------------------------------------------
OPS = st.lists(
    st.one_of(
        st.tuples(st.just("obs"), st.integers(0, 5), st.integers(0, 4), st.integers(1, 3)),
        st.tuples(st.just("del"), st.integers(0, 5), st.just(0), st.just(0)),
        st.tuples(st.just("step"), st.just(0), st.just(0), st.just(0)),
    ),
    min_size=1,
    max_size=40,
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ops=OPS, method=st.sampled_from(["bayes", "threshold"]), seed=st.integers(0, 1000))
def test_random_operation_sequences_keep_invariants(ops: list, method: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    kw = {"min_observations": 2} if method == "bayes" else {"n_votes": 2}
    m = make_identity_manager(method, max_features_per_face=4, **kw)
    dead: set[int] = set()
    t = 0.0
    for op, track, person, n in [*ops, ("step", 0, 0, 0)]:
        t += 0.1
        if op == "obs":
            accepted = m.add_observations(
                track + 100 * len([d for d in dead if d % 100 == track]), _person(person, n, rng), t
            )
            assert accepted
        elif op == "del":
            tid = track + 100 * len([d for d in dead if d % 100 == track])
            m.track_deleted(tid, t)
            dead.add(tid)
        else:
            m.step(t)
        assigned = m.assigned_tracks()
        faces = list(assigned.values())
        assert len(faces) == len(set(faces))  # one face per live track, never shared
        assert set(m.available_face_ids()) == set(m.face_ids()) - set(faces)
        assert m.face_ids() == list(range(1, len(m.face_ids()) + 1))  # stable ids from 1
        for f in m.face_ids():
            assert 1 <= len(m.face_features(f)) <= 4
        for tid in m.live_track_ids():
            assert 0.0 <= m.confidence_of(tid) <= 1.0
        if isinstance(m, FaceIdentityManager):
            p, rows, cols = m.posterior_table()
            assert p.shape == (1 + len(rows), 1 + len(cols)) and cols == m.available_face_ids()
            assert not set(rows) & set(assigned)
            assert p[0, 0] == 0.0 and np.all((p >= 0.0) & (p <= 1.0))
            if m.is_normalised and rows:
                slack = 1e-6 + (len(cols) + 1) * m.clamp_probability
                assert np.all(np.abs(p[1:].sum(axis=1) - 1.0) <= slack)
                assert np.all(np.abs(p[:, 1:].sum(axis=0) - 1.0) <= slack)


# ------------------------------------------------------------------------------------------------
# Real faces: re-identification of the fixture people with real ONNX embeddings
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lfw_embeddings() -> dict[str, np.ndarray]:
    """identity -> (10, 128) embeddings of the committed LFW photos (largest face of each)."""
    cv2 = pytest.importorskip("cv2")
    try:
        from face_reid_camera.faces.alignment import align_face
        from face_reid_camera.faces.embedder import FaceEmbedder
    except ImportError:
        pytest.skip("face_reid_camera.faces.embedder not available")
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    embedder = FaceEmbedder(num_threads=1)
    out = {}
    for folder in sorted(FACES_DIR.glob("lfw_*")):
        chips = []
        for path in sorted(folder.glob("*.jpg")):
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            detector.setInputSize((image.shape[1], image.shape[0]))
            _, faces = detector.detect(image)
            largest = faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]
            chips.append(align_face(image, largest[4:14].reshape(5, 2)))
        out[folder.name] = embedder.embed(np.stack(chips))
    return out


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_real_faces_are_reidentified_across_visits(
    lfw_embeddings: dict[str, np.ndarray], method: str
) -> None:
    m = make_identity_manager(method)
    people = sorted(lfw_embeddings)
    first_face: dict[str, int] = {}
    t = 0.0
    # visit 1: photos 0..4, one per frame, then the person leaves; visit 2: photos 5..9
    for visit, photos in enumerate((range(0, 5), range(5, 10))):
        for k, person in enumerate(people):
            tid = 1000 * visit + k
            events = []
            for i in photos:
                m.add_observations(tid, lfw_embeddings[person][i : i + 1], t)
                events += m.step(t)
                t += 0.1
            m.track_deleted(tid, t)
            events += m.step(t)
            decided = [e for e in events if e.kind != RELEASED]
            assert len(decided) == 1, (person, events)
            if visit == 0:
                assert decided[0].kind == NEW
                first_face[person] = decided[0].face_id
            else:
                assert decided[0].kind == ASSIGNED and decided[0].face_id == first_face[person], person
    assert sorted(first_face.values()) == list(range(1, len(people) + 1))


def test_min_of_k_likelihood_prevents_merging_a_stranger_into_a_well_learned_face() -> None:
    """A face with 50 features 0.3 from its centre; a stranger 0.47 from that centre in an orthogonal
    direction is ~0.56 from every stored feature: a positive single pair, but far too far for the minimum
    over 50 features of the same person.  The paper's pair likelihood merges, the min-of-K one does not.
    (Densities of a fit on clean photo pairs, test/data/faces, whose N_p = N_n crossing is 0.61.)"""
    clean_photo_fit = LikelihoodModel(SkewNormal(1.616, 0.3613, 0.09734), SkewNormal(1.729, 0.7101, 0.1223))
    rng = np.random.default_rng(20)
    centre = _e(0, 0.7)
    spread = rng.normal(0, 1, (50, DIM))
    spread[:, 100:] = 0.0
    spread[:, 0] = 0.0
    spread *= 0.3 / np.linalg.norm(spread, axis=1, keepdims=True)
    face = (centre + spread).astype(np.float32)
    stranger = (centre + _e(110, 0.47) + rng.normal(0, 0.002, (3, DIM))).astype(np.float32)
    outcomes = {}
    for name, model in (
        ("paper", clean_photo_fit),
        ("min_of_k", clean_photo_fit.with_k_exponents(0.538, 0.339)),  # opt-in --fit-min-of-k
    ):
        m = FaceIdentityManager(model, min_observations=3)
        m.import_faces([LearnedFace(1, face)])
        events = []
        for i in range(3):
            m.add_observations(5, stranger[i : i + 1], float(i))
            events += m.step(float(i))
        outcomes[name] = _kinds(events)
    assert outcomes["paper"] == [(ASSIGNED, 5, 1)]
    assert outcomes["min_of_k"] == [(NEW, 5, 2)]


def test_log_ratio_cap_limits_the_evidence_of_one_observation() -> None:
    rng = np.random.default_rng(21)
    conf = []
    for cap in (None, 1.0):
        m = _manager_with_faces(3, np.random.default_rng(22), max_abs_log_likelihood_ratio=cap)
        m.add_observations(10, _person(1, 1, rng), 0.0)
        m.step(0.0)
        conf.append(m.posterior_of(10)[2])
    assert conf[0] > 0.99 and conf[1] < 0.9


# ------------------------------------------------------------------------------------------------
# forget_face: deleting a learned person (privacy)
# ------------------------------------------------------------------------------------------------
def test_forget_available_face_removes_it_and_its_table_column() -> None:
    rng = np.random.default_rng(30)
    m = _manager_with_faces(3, rng, min_observations=3)
    _feed(m, 10, 1, rng, 0.0)  # an unassigned track with evidence for face 2
    assert m.posterior_of(10)[2] > 0.5
    assert m.forget_face(2) is True
    assert m.face_ids() == [1, 3] and m.available_face_ids() == [1, 3]
    assert 2 not in m.posterior_of(10) and m.posterior_table()[2] == [1, 3]
    assert [f.face_id for f in m.export_faces()] == [1, 3]
    with pytest.raises(KeyError):
        m.face_features(2)
    assert m.forget_face(2) is False and m.forget_face(99) is False
    assert m.stats.faces_forgotten == 1
    # person 1 is now a stranger: a new id, never the forgotten one, holding only the new observations
    events = _feed(m, 10, 1, rng, 0.1) + _feed(m, 10, 1, rng, 0.2)
    assert _kinds(events) == [(NEW, 10, 4)]
    assert len(m.face_features(4)) == 3
    with pytest.raises(ValueError):
        m.forget_face("2")  # type: ignore[arg-type]


def test_forget_face_of_a_live_track_makes_the_track_unidentified_again() -> None:
    rng = np.random.default_rng(31)
    m = _manager_with_faces(3, rng, min_observations=3)
    for i in range(3):
        _feed(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2
    m.add_observations(10, _person(1, 2, rng), 0.5)  # queued before the forget: dropped with the face
    assert m.forget_face(2)
    assert m.face_id_of(10) is None and m.assigned_tracks() == {} and m.confidence_of(10) == 0.0
    assert m.face_ids() == [1, 3] and m.available_face_ids() == [1, 3]
    assert 10 in m.live_track_ids()
    assert m.step(0.6) == []  # the queued observations were dropped: nothing to classify
    assert m.posterior_of(10) == {}
    events = []
    for i in range(3):  # still in view: learned again, from scratch, under a new id
        events += _feed(m, 10, 1, rng, 1.0 + 0.1 * i)
    assert _kinds(events) == [(NEW, 10, 4)]
    assert len(m.face_features(4)) == 3 and m.export_faces()[-1].n_observations == 3
    m.track_deleted(10, 2.0)
    assert _kinds(m.step(2.0)) == [(RELEASED, 10, 4)]
    assert m.available_face_ids() == [1, 3, 4]


def test_forget_face_of_a_track_being_deleted_emits_no_release() -> None:
    rng = np.random.default_rng(32)
    m = _manager_with_faces(1, rng, min_observations=2)
    for i in range(2):
        _feed(m, 10, 0, rng, 0.1 * i)
    assert m.face_id_of(10) == 1
    m.track_deleted(10, 1.0)
    assert m.forget_face(1)
    assert m.step(1.0) == [] and m.face_ids() == [] and m.live_track_ids() == []


def test_threshold_forget_face_drops_votes_for_it() -> None:
    rng = np.random.default_rng(33)
    m = ThresholdIdentityManager(distance_threshold=0.6, n_votes=3)
    m.import_faces([LearnedFace(j + 1, _person(j, 5, rng)) for j in range(3)])
    for i in range(2):
        m.add_observations(10, _person(1, 1, rng), 0.1 * i)
        assert m.step(0.1 * i) == []
    assert m.confidence_of(10) == 1.0  # 2 votes for face 2
    assert m.forget_face(2)
    assert m.confidence_of(10) == 0.0  # its votes are gone
    events = []
    for i in range(3):
        m.add_observations(10, _person(1, 1, rng), 1.0 + 0.1 * i)
        events += m.step(1.0 + 0.1 * i)
    assert _kinds(events) == [(NEW, 10, 4)]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ops=st.lists(
        st.one_of(
            st.tuples(st.just("obs"), st.integers(0, 4), st.integers(0, 4)),
            st.tuples(st.just("del"), st.integers(0, 4), st.just(0)),
            st.tuples(st.just("forget"), st.integers(1, 6), st.just(0)),
            st.tuples(st.just("step"), st.just(0), st.just(0)),
        ),
        min_size=1,
        max_size=40,
    ),
    method=st.sampled_from(["bayes", "threshold"]),
)
def test_random_sequences_with_forget_keep_invariants(ops: list, method: str) -> None:
    rng = np.random.default_rng(len(ops))
    kw = {"min_observations": 2} if method == "bayes" else {"n_votes": 2}
    m = make_identity_manager(method, max_features_per_face=4, **kw)
    generation = dict.fromkeys(range(5), 0)
    forgotten: set[int] = set()
    t = 0.0
    for op, a, b in [*ops, ("step", 0, 0)]:
        t += 0.1
        if op == "obs":
            m.add_observations(a + 100 * generation[a], _person(b, 1, rng), t)
        elif op == "del":
            m.track_deleted(a + 100 * generation[a], t)
            generation[a] += 1
        elif op == "forget":
            known = a in m.face_ids()
            assert m.forget_face(a) is known
            if known:
                forgotten.add(a)
        else:
            m.step(t)
        faces = list(m.assigned_tracks().values())
        assert len(faces) == len(set(faces))
        assert set(m.available_face_ids()) == set(m.face_ids()) - set(faces)
        assert not forgotten & set(m.face_ids())  # a forgotten id never comes back
        for f in m.face_ids():
            assert 1 <= len(m.face_features(f)) <= 4
        if isinstance(m, FaceIdentityManager):
            p, rows, cols = m.posterior_table()
            assert p.shape == (1 + len(rows), 1 + len(cols)) and cols == m.available_face_ids()
            assert not set(rows) & set(m.assigned_tracks())


def test_export_face_snapshots_one_face() -> None:
    rng = np.random.default_rng(34)
    m = FaceIdentityManager(min_observations=2)
    for t in range(2):
        _feed(m, 1, 0, rng, 10.0 + t)
    one = m.export_face(1)
    (all_,) = m.export_faces()
    assert (one.face_id, one.name, one.created_s, one.last_seen_s, one.n_observations) == (1, None, 11.0, 11.0, 2)
    assert one.features.tobytes() == all_.features.tobytes() and one.n_observations == all_.n_observations
    one.features[:] = 0.0  # a copy: the manager is unaffected
    assert np.any(m.face_features(1) != 0.0)
    _feed(m, 1, 0, rng, 12.0)
    assert m.export_face(1).n_observations == 3 and m.export_face(1).last_seen_s == 12.0
    m.forget_face(1)
    with pytest.raises(KeyError):
        m.export_face(1)


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_feature_gate_keeps_a_swapped_persons_features_out_of_the_face(method: str) -> None:
    """A track identified as person 0 that the tracker then puts on person 1: with the gate, face 1
    learns nothing of person 1 (and person 1's later track is not mistaken for it); without, it does."""
    learned = {}
    for gate in (None, 0.6):
        rng = np.random.default_rng(11)
        m = make_identity_manager(method, min_observations=1, feature_gate_distance=gate) if method == "bayes" \
            else make_identity_manager(method, n_votes=1, feature_gate_distance=gate)
        m.import_faces([LearnedFace(1, _person(0, 5, rng))])
        _feed(m, 10, 0, rng, 0.0)
        assert m.face_id_of(10) == 1
        for i in range(6):  # swapped: the track now follows person 1
            _feed(m, 10, 1, rng, 0.1 * (i + 1))
        feats = m.face_features(1)
        learned[gate] = feats
        of_person_1 = (np.linalg.norm(feats - CENTRES[1][None, :], axis=1)
                       < np.linalg.norm(feats - CENTRES[0][None, :], axis=1))
        if gate is None:
            assert of_person_1.sum() == 6  # the paper: the face absorbed person 1
        else:
            assert of_person_1.sum() == 0 and m.stats.observations_not_learned_inconsistent == 6
            assert len(feats) == 5 + 1
    assert len(learned[None]) == 5 + 1 + 6


def test_default_gate_is_the_likelihood_crossing() -> None:
    model = LikelihoodModel.default()
    d = model.decision_distance
    lr = model.log_likelihood_ratio([d - 0.01, d + 0.01])
    assert lr[0] > 0 > lr[1]
    with pytest.raises(ValueError, match="feature_gate_distance"):
        FaceIdentityManager(feature_gate_distance=0.0)
