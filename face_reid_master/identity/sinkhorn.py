"""Sinkhorn normalisation of the posterior table with a slack row and column (Koide et al. 2017, III-E).

Rows 1..N (tracks) and columns 1..M (learned faces) are scaled to sum to 1; row 0 ("face not tracked")
and column 0 ("new person") absorb the remainder, so a track may be new and a face may be absent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["SinkhornResult", "sinkhorn_with_slack"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class SinkhornResult:
    """Normalised table, iterations used, whether it met the tolerance, final max |row sum - 1|."""

    table: FloatArray
    iterations: int
    converged: bool
    max_row_error: float


def sinkhorn_with_slack(
    table: npt.ArrayLike, tolerance: float = 1e-6, max_iterations: int = 100, solver: str = "newton"
) -> SinkhornResult:
    """Sinkhorn normalisation of a (1+N) x (1+M) table with slack row 0 and slack column 0.

    Finds P = diag(a) K diag(b), a_0 = b_0 = 1, whose rows 1..N and columns 1..M sum to 1 (row 0 and
    column 0 are never normalised themselves; cell (0, 0) is untouched): the fixed point of the paper's
    alternating row / column normalisation.  ``solver="sinkhorn"`` runs exactly those alternations (rows
    first), two matrix-vector products each; ``"newton"`` (default) reaches the same fixed point with
    damped Newton steps on the convex scaling potential, which takes a handful of iterations where the
    alternations crawl (tables with near-certain matches need hundreds).  Stops when, after a column
    normalisation, every normalised row sums to 1 within ``tolerance``, or after ``max_iterations``.
    """
    k = np.array(table, dtype=np.float64)
    if k.ndim != 2 or k.shape[0] < 1 or k.shape[1] < 1:
        raise ValueError(f"table must be 2-D with at least one row and column, got shape {k.shape}")
    if not np.all(np.isfinite(k)) or np.any(k < 0.0):
        raise ValueError("table entries must be finite and >= 0")
    if not (tolerance > 0.0) or max_iterations < 1:
        raise ValueError("tolerance must be > 0 and max_iterations >= 1")
    if solver not in ("newton", "sinkhorn"):
        raise ValueError(f"solver must be 'newton' or 'sinkhorn', got {solver!r}")
    n, m = k.shape[0] - 1, k.shape[1] - 1
    if n == 0 and m == 0:
        return SinkhornResult(k, 0, True, 0.0)
    if n and np.any(k[1:].max(axis=1) <= 0.0):
        raise ValueError("a normalised row (1..N) of the table sums to 0")
    if m and np.any(k[:, 1:].max(axis=0) <= 0.0):
        raise ValueError("a normalised column (1..M) of the table sums to 0")
    if solver == "newton" and n and m:
        a, b, iterations = _newton_scaling(k, tolerance, max_iterations)
        b[1:] = 1.0 / (a @ k[:, 1:])  # finish on a column pass, as the alternations do
        err = float(np.max(np.abs(a[1:] * (k[1:] @ b) - 1.0)))
        converged = err < tolerance
    else:
        a, b, iterations, err, converged = _alternate(k, tolerance, max_iterations)
    out = k * a[:, None] * b[None, :]
    out[0, 0] = k[0, 0]
    return SinkhornResult(out, iterations, converged, err)


def _alternate(
    k: FloatArray, tolerance: float, max_iterations: int
) -> tuple[FloatArray, FloatArray, int, float, bool]:
    """The paper's alternating normalisation on the scaling vectors."""
    n, m = k.shape[0] - 1, k.shape[1] - 1
    a = np.ones(n + 1)
    b = np.ones(m + 1)
    k_rows = k[1:]
    k_cols = k[:, 1:]
    iterations = 0
    err = 0.0
    while True:
        row_sums = k_rows @ b  # sums of rows 1..N with the current column scales
        err = float(np.max(np.abs(a[1:] * row_sums - 1.0))) if n else 0.0
        if iterations > 0 and err < tolerance:
            return a, b, iterations, err, True
        if iterations >= max_iterations:
            return a, b, iterations, err, False
        if n:
            a[1:] = 1.0 / row_sums
        if m:
            b[1:] = 1.0 / (a @ k_cols)
        iterations += 1


def _newton_scaling(
    k: FloatArray, tolerance: float, max_iterations: int
) -> tuple[FloatArray, FloatArray, int]:
    """Damped Newton on phi(x, y) = sum_ij K_ij e^(x_i + y_j) - sum_i x_i - sum_j y_j (x_0 = y_0 = 0).

    grad phi = (row sums - 1, column sums - 1); the Hessian [[diag R, B], [B^T, diag C]] (B = P[1:, 1:])
    is solved through its N x N Schur complement diag R - B diag(1/C) B^T, strictly diagonally dominant
    thanks to the slack column, so each step costs O(N^2 M).  Backtracking (Armijo) keeps it global.
    """
    n = k.shape[0] - 1
    x = np.zeros(n + 1)
    y = np.zeros(k.shape[1])
    a = np.ones(n + 1)
    b = np.ones(k.shape[1])
    # one alternation first: a cheap, well-scaled starting point
    a[1:] = 1.0 / (k[1:] @ b)
    b[1:] = 1.0 / (a @ k[:, 1:])
    x[1:] = np.log(a[1:])
    y[1:] = np.log(b[1:])
    kb = k @ b
    phi = float(a @ kb) - x.sum() - y.sum()
    iterations = 1
    while iterations < max_iterations:
        row = a * kb
        col = b * (a @ k)
        f = row[1:] - 1.0
        g = col[1:] - 1.0
        if max(float(np.abs(f).max()), float(np.abs(g).max())) < 0.5 * tolerance:
            break
        bmat = k[1:, 1:] * a[1:, None] * b[None, 1:]
        inv_c = 1.0 / col[1:]
        schur = np.diag(row[1:]) - (bmat * inv_c[None, :]) @ bmat.T
        dx = np.linalg.solve(schur, -f + bmat @ (inv_c * g))
        dy = inv_c * (-g - bmat.T @ dx)
        slope = float(f @ dx + g @ dy)
        t = 1.0
        while True:
            xn = x.copy()
            yn = y.copy()
            xn[1:] += t * dx
            yn[1:] += t * dy
            an = np.exp(xn)
            bn = np.exp(yn)
            kbn = k @ bn
            phin = float(an @ kbn) - xn.sum() - yn.sum()
            if phin <= phi + 1e-4 * t * slope or t < 1e-8:
                break
            t *= 0.5
        x, y, a, b, kb, phi = xn, yn, an, bn, kbn, phin
        iterations += 1
    return a, b, iterations

