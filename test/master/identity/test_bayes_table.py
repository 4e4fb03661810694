"""Tests of the Bayesian posterior table: likelihood-ratio update, Sinkhorn, decisions."""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np
import pytest
from identity_test_helpers import (
    ASSIGNED,
    CENTRES,
    DIM,
    NEW,
    NOISE,
    event_kinds,
    manager_with_faces,
    unit_vector,
)
from scipy import optimize, stats

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.feature_bank import min_distances_to_faces
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal
from face_reid_master.identity.records import LearnedFace
from face_reid_master.identity.size_likelihood import default_face_likelihood

# ------------------------------------------------------------------------------------------------
# Hand-computed Bayesian update + Sinkhorn (2 tracks x 2 faces + slack)
# ------------------------------------------------------------------------------------------------
# Normal likelihoods N_p = N(0, s^2), N_n = N(1, s^2) with s^2 = 1 / (2 ln 2):
# log N_p(d)/N_n(d) = ((d - 1)^2 - d^2) / (2 s^2) = (1 - 2d) ln 2, i.e. N_p/N_n = 2^(1 - 2d):
# d = 0 -> 2, d = 0.5 -> 1, d = 1 -> 1/2.
SIGMA = 1.0 / math.sqrt(2.0 * math.log(2.0))
SIMPLE = LikelihoodModel(SkewNormal(0.0, 0.0, SIGMA), SkewNormal(0.0, 1.0, SIGMA))


def _two_by_two(c: float, iterations: int, solver: str = "sinkhorn") -> BayesIdentityManager:
    """Faces 1 (feature 0) and 2 (feature e_0), track A at 0, track B at e_0 / 2, one observation each."""
    m = BayesIdentityManager(
        SIMPLE.with_new_person_scale(c),
        prior_probability=0.1,
        min_observations=1000,  # no decisions: inspect the table
        sinkhorn_max_iterations=iterations,
        sinkhorn_tolerance=1e-13,
        sinkhorn_solver=solver,
    )
    m.faces.import_faces([LearnedFace(1, np.zeros((1, DIM), np.float32)), LearnedFace(2, unit_vector(0)[None])])
    m.add_observations(100, np.zeros((1, DIM), np.float32), 0.0)  # d = 0 to face 1, 1 to face 2
    m.add_observations(200, unit_vector(0, 0.5)[None], 0.0)  # d = 0.5 to both faces
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
    m = BayesIdentityManager(
        SIMPLE, min_observations=1000, sinkhorn_max_iterations=5000, sinkhorn_tolerance=1e-13
    )
    m.faces.import_faces([LearnedFace(j + 1, f) for j, f in enumerate(faces)])
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


def test_new_person_scale_c_biases_towards_new_faces() -> None:
    rng = np.random.default_rng(11)
    obs = (CENTRES[1] + CENTRES[2]) / 2 + rng.normal(0, NOISE, (1, DIM)).astype(np.float32)  # ambiguous
    posts = []
    for c in (1.0, 100.0):
        m = manager_with_faces(
            3,
            np.random.default_rng(12),
            likelihood=default_face_likelihood().pooled.with_new_person_scale(c),
            min_observations=100,
        )
        m.add_observations(10, obs, 0.0)
        m.step(0.0)
        posts.append(m.posterior_of(10)[0])
    assert posts[1] > posts[0]


def test_min_of_k_likelihood_prevents_merging_a_stranger_into_a_well_learned_face() -> None:
    """A face with 50 features 0.3 from its centre; a stranger 0.47 from that centre in an orthogonal
    direction is ~0.56 from every stored feature: a positive single pair, but far too far for the minimum
    over 50 features of the same person.  The paper's pair likelihood merges, the min-of-K one does not.
    (Densities of a fit on clean photo pairs, test/data/faces, whose N_p = N_n crossing is 0.61.)"""
    clean_photo_fit = LikelihoodModel(SkewNormal(1.616, 0.3613, 0.09734), SkewNormal(1.729, 0.7101, 0.1223))
    rng = np.random.default_rng(20)
    centre = unit_vector(0, 0.7)
    spread = rng.normal(0, 1, (50, DIM))
    spread[:, 100:] = 0.0
    spread[:, 0] = 0.0
    spread *= 0.3 / np.linalg.norm(spread, axis=1, keepdims=True)
    face = (centre + spread).astype(np.float32)
    stranger = (centre + unit_vector(110, 0.47) + rng.normal(0, 0.002, (3, DIM))).astype(np.float32)
    outcomes = {}
    for name, model in (
        ("paper", clean_photo_fit),
        ("min_of_k", dataclasses.replace(clean_photo_fit, k_exponent_positive=0.538,
                                         k_exponent_negative=0.339)),  # opt-in --fit-min-of-k
    ):
        m = BayesIdentityManager(model, min_observations=3)
        m.faces.import_faces([LearnedFace(1, face)])
        events = []
        for i in range(3):
            m.add_observations(5, stranger[i : i + 1], float(i))
            events += m.step(float(i))
        outcomes[name] = event_kinds(events)
    assert outcomes["paper"] == [(ASSIGNED, 5, 1)]
    assert outcomes["min_of_k"] == [(NEW, 5, 2)]


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
        {"max_features_per_face": 0},
        {"embedding_dim": 0},
        {"shortlist_faces": 0},
        {"likelihood": "default"},
        {"min_observations": 2.5},
    ],
)
def test_bad_constructor_arguments_raise(kw: dict) -> None:
    with pytest.raises(ValueError):
        BayesIdentityManager(**kw)


def test_default_gate_is_the_likelihood_crossing() -> None:
    model = default_face_likelihood().pooled
    d = model.decision_distance
    lr = model.log_likelihood_ratio([d - 0.01, d + 0.01])
    assert lr[0] > 0 > lr[1]
    with pytest.raises(ValueError, match="feature_gate_distance"):
        BayesIdentityManager(feature_gate_distance=0.0)
