"""Tests of the Sinkhorn normalisation with slack row and column."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.identity.sinkhorn import sinkhorn_with_slack


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
