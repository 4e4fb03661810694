"""Glance-weighted evidence: correlated frames of one camera's glance count as n / (1 + (n - 1) rho)."""

from __future__ import annotations

import numpy as np
import pytest
from identity_test_helpers import ASSIGNED, CENTRES, DIM, NEW, event_kinds, person_obs, unit_vector

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.glance_evidence import GlanceEvidence
from face_reid_master.identity.records import LearnedFace


def _feed(g: GlanceEvidence, rows: np.ndarray, source: str = "cam", t0: float = 0.0, dt: float = 0.1,
          track: int = 1) -> np.ndarray:
    """Feed rows one per update; the summed deltas = what the glance(s) put in the table."""
    return sum(g.update(track, source, t0 + k * dt, rows[k:k + 1]) for k in range(rows.shape[0]))


def test_independent_evidence_is_the_plain_sum() -> None:
    rows = np.random.default_rng(0).normal(size=(7, 3))
    for g in (GlanceEvidence(gap_s=1.0, correlation=0.0), GlanceEvidence(gap_s=0.0, correlation=0.7)):
        g.add_column(), g.add_column()
        assert g.independent
        np.testing.assert_allclose(_feed(g, rows), rows.sum(axis=0), rtol=1e-12)
        assert g.open_glances(1) == 0  # nothing kept


@pytest.mark.parametrize("rho", [0.25, 0.5, 1.0])
def test_one_glance_of_equal_frames_is_worth_n_eff(rho: float) -> None:
    g = GlanceEvidence(gap_s=0.5, correlation=rho)
    g.add_column()
    row = np.array([[0.0, 2.0]])
    total = _feed(g, np.repeat(row, 10, axis=0))
    n_eff = 10 / (1 + 9 * rho)
    np.testing.assert_allclose(total, n_eff * row[0], rtol=1e-12)
    assert total[1] < 10 * row[0, 1]


def test_a_glance_counts_the_mean_of_its_frames_not_the_first_one() -> None:
    g = GlanceEvidence(gap_s=0.5, correlation=1.0)
    g.add_column()
    rows = np.array([[0.0, 4.0], [0.0, -2.0], [0.0, 1.0]])
    np.testing.assert_allclose(_feed(g, rows), [0.0, 1.0], atol=1e-12)  # the mean, counted once


def test_a_gap_or_another_camera_starts_a_new_glance() -> None:
    g = GlanceEvidence(gap_s=0.5, correlation=1.0)
    g.add_column()
    row = np.array([[0.0, 1.5]])
    first = _feed(g, np.repeat(row, 5, axis=0), t0=0.0)  # 0.0 .. 0.4 s
    after_gap = _feed(g, np.repeat(row, 5, axis=0), t0=1.5)  # more than gap_s later: a new glance
    other_camera = _feed(g, np.repeat(row, 5, axis=0), source="cam2", t0=1.5)  # the same time, another camera
    for part in (first, after_gap, other_camera):
        np.testing.assert_allclose(part, row[0], atol=1e-12)
    assert g.open_glances(1) == 2  # one per camera


def test_a_face_joining_mid_glance_is_judged_on_its_own_observations() -> None:
    g = GlanceEvidence(gap_s=1.0, correlation=1.0)
    g.add_column()
    total = _feed(g, np.array([[0.0, 1.0], [0.0, 1.0]]))
    g.add_column()  # a face joins face_list: a third column
    total = np.append(total, 0.0) + _feed(g, np.array([[0.0, 1.0, -3.0]]), t0=0.2)
    np.testing.assert_allclose(total, [0.0, 1.0, -3.0], atol=1e-12)
    g.remove_columns([1])  # the first face leaves: the other column's glance state stays
    np.testing.assert_allclose(_feed(g, np.array([[0.0, -3.0]]), t0=0.3), [0.0, 0.0], atol=1e-12)


def test_forgotten_tracks_lose_their_glances_and_bad_input_raises() -> None:
    g = GlanceEvidence(gap_s=1.0, correlation=0.5)
    g.update(7, "cam", 0.0, np.zeros((1, 1)))
    assert g.open_glances(7) == 1
    g.forget_track(7)
    assert g.open_glances(7) == 0
    with pytest.raises(ValueError, match="columns"):
        g.update(7, "cam", 0.0, np.zeros((1, 3)))
    with pytest.raises(ValueError, match="correlation"):
        GlanceEvidence(correlation=1.5)
    with pytest.raises(ValueError, match="gap_s"):
        GlanceEvidence(gap_s=-1.0)
    with pytest.raises(ValueError, match="correlation"):
        BayesIdentityManager(glance_correlation=-0.1)


def _manager(rho: float) -> BayesIdentityManager:
    m = BayesIdentityManager(glance_gap_s=0.5, glance_correlation=rho, embedding_dim=DIM)
    m.import_faces([LearnedFace(1, person_obs(0, 5, np.random.default_rng(1)))])
    return m


def test_a_long_glance_does_not_outvote_like_many_glances() -> None:
    obs = (CENTRES[0] + unit_vector(5, 0.5))[None, :].astype(np.float32)  # 0.5 from face 1: weak evidence
    decided = {}
    for rho in (0.0, 1.0):
        m = _manager(rho)
        first = None
        for k in range(20):  # one camera, 20 frames at 10 Hz: one glance
            m.add_observations(10, obs, 0.1 * k, source="cam_a")
            if event_kinds(m.step(0.1 * k)) == [(ASSIGNED, 10, 1)]:
                decided[rho] = k + 1
                break
            first = first or m.posterior_of(10)[1]
            assert m.posterior_of(10)[1] == pytest.approx(first, abs=1e-9) or rho == 0.0
        if rho == 1.0:  # the glance counted once, like its first frame; a second camera's glance adds to it
            assert rho not in decided and first < 0.95
            m.add_observations(10, obs, 2.0, source="cam_b")
            m.step(2.0)
            assert m.face_id_of(10) == 1 or m.posterior_of(10)[1] > first + 1e-3
    assert decided[0.0] <= 10  # independent frames pile up: the paper decides within one second


def test_glance_bookkeeping_with_vanishing_correlation_reproduces_the_papers_table() -> None:
    runs = []
    for rho in (0.0, 1e-12):  # 1e-12 takes the glance path: deltas per glance instead of plain sums
        m = BayesIdentityManager(embedding_dim=DIM, glance_gap_s=5.0, glance_correlation=rho)
        m.import_faces([LearnedFace(j + 1, person_obs(j, 5, np.random.default_rng(j))) for j in range(3)])
        r = np.random.default_rng(3)
        events = []
        for k in range(6):
            m.add_observations(20, person_obs(1, 1, r), 0.1 * k, source="a")
            m.add_observations(20, person_obs(1, 1, r), 0.1 * k, source="b")
            m.add_observations(21, person_obs(6, 1, r), 0.1 * k, source="b")
            events += m.step(0.1 * k)
        runs.append((m.posterior_table()[0], event_kinds(events)))
    assert runs[0][1] == runs[1][1]
    assert any(kind == NEW for kind, _, _ in runs[0][1])  # the stranger became a new face
    np.testing.assert_allclose(runs[0][0], runs[1][0], atol=1e-9)
