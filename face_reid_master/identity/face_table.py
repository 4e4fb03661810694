"""Face-ID assignment of people tracks: Algorithm 1 + Bayesian face table of Koide et al. 2017 (III-D, III-E).

Pure core of the master node (no ROS).  The node feeds face embeddings per track
(:meth:`IdentityManagerBase.add_observations`), track deaths (:meth:`~IdentityManagerBase.track_deleted`)
and calls :meth:`~IdentityManagerBase.step` once per update; it gets back identity events.

Posterior table (paper Fig. 5, OpenPTrack ``FaceRecognizerBayes``)::

                 col 0 "new person"   col j = learned face available for assignment (face_list)
    row 0         (unused, 0)          p(x_0j): face j's person is not tracked (slack)
    row i         p(x_i0)              p(x_ij): unassigned track i is face j

Likelihood (the form implemented, per face observation y of track i, distances d_ik = min over face k's
stored features, eq. 4): under x_ij (j >= 1) d_ij is a positive pair and every other d_ik a negative one;
under x_i0 all d_ik are negative pairs; c (``new_person_scale_c``) scales the "new person" hypothesis::

    p(y | x_ij) = N_p(d_ij) * prod_{k != j} N_n(d_ik)          p(y | x_i0) = c * prod_k N_n(d_ik)

Dividing row i by the common factor prod_k N_n(d_ik) (rows are renormalised, so a per-row factor changes
nothing) leaves: column j *= N_p(d_ij) / N_n(d_ij), column 0 *= c.  This is exactly the product of the
paper's eq. 5 over all learned faces, i.e. what OpenPTrack computes (it multiplies the row, for every face
k, by N_p(d_ik) in k's column, N_n(d_ik) elsewhere and c*N_n(d_ik) in column 0) except that OpenPTrack
applies c once per learned face (c^M per observation) where this applies it once per observation; the two
are identical for the paper's c = 1.  Evidence is accumulated in log space and rescaled by the row
maximum before exponentiation, so nothing under/overflows.  Then Sinkhorn normalisation (rows 1..N and
columns 1..M sum to 1; row 0 / column 0 are slack), clamping to [clamp, 1 - clamp] (OpenPTrack: 1e-3),
and a decision when p(x_ij) > posterior_threshold and the track has >= min_observations compared with j.

One deliberate extension (:class:`~face_reid_master.identity.likelihood.LikelihoodModel` k-exponents; 0 = the paper):
d_ij is a minimum over face j's K stored features, so N_p/N_n (fitted on single pairs) is replaced by the
density of a minimum of K_eff = K**e pairs.  Without it a stranger's minimum distance to a face holding
50 features looks like a positive pair and gets merged into that face (measured on a CelebA re-entry
simulation, 100 people, 900 visits: 93 of 631 known-person decisions wrong with the paper's form, 0 of
601 with the extension).

Scaling: each face's bounded feature set lives in one padded float32 block, so eq. 4 for all unassigned
observations is one GEMM (||f||^2 - 2 q.f with ||f||^2 carried as an extra column); above
``exact_search_max_features`` stored features only the ``shortlist_faces`` faces with the nearest
centroids are compared exactly and the others get the weakest evidence.  Observations of identified
tracks never need distances to other faces.
"""

from __future__ import annotations

import enum
import math
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.likelihood import LikelihoodModel

__all__ = [
    "FaceIdentityManager",
    "IdentityEvent",
    "IdentityEventKind",
    "IdentityManagerBase",
    "IdentityStats",
    "LearnedFace",
    "SinkhornResult",
    "ThresholdIdentityManager",
    "make_identity_manager",
    "min_distances_to_faces",
    "select_diverse_subset",
    "sinkhorn_with_slack",
]

FloatArray = npt.NDArray[np.float64]
F32Array = npt.NDArray[np.float32]


# --------------------------------------------------------------------------------------------- records
class IdentityEventKind(str, enum.Enum):
    """What happened to a track's face identity."""

    ASSIGNED_KNOWN = "assigned_known"  # the track was recognised as a learned face (re-identification)
    NEW_FACE = "new_face"  # the track is an unknown person: a new face id was created for it
    RELEASED = "released"  # the track died: its face goes back to face_list (assignable again)


@dataclass(frozen=True)
class IdentityEvent:
    """One identity change, returned by :meth:`IdentityManagerBase.step`."""

    kind: IdentityEventKind
    track_id: int
    face_id: int
    stamp_s: float
    confidence: float  # posterior (Bayes) or vote fraction (threshold) when the decision was made


@dataclass
class LearnedFace:
    """A learned face for export/import (persistent memory): id, bounded feature set, optional name."""

    face_id: int
    features: F32Array  # (k, embedding_dim) float32, k >= 1
    name: str | None = None
    created_s: float = 0.0
    last_seen_s: float = 0.0
    n_observations: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.face_id, bool) or not isinstance(self.face_id, (int, np.integer)):
            raise ValueError(f"LearnedFace.face_id must be an int, got {self.face_id!r}")
        if int(self.face_id) < 1:
            raise ValueError(f"LearnedFace.face_id must be >= 1, got {self.face_id}")
        self.face_id = int(self.face_id)
        feats = np.asarray(self.features)
        if feats.ndim != 2 or feats.shape[0] < 1 or feats.shape[1] < 1:
            raise ValueError(f"LearnedFace.features must have shape (k >= 1, dim), got {feats.shape}")
        if not np.issubdtype(feats.dtype, np.floating):
            raise ValueError(f"LearnedFace.features must be floating point, got {feats.dtype}")
        if not np.all(np.isfinite(feats)):
            raise ValueError(f"LearnedFace {self.face_id}: features contain NaN or Inf")
        self.features = np.ascontiguousarray(feats, dtype=np.float32)
        if self.name is not None and not isinstance(self.name, str):
            raise ValueError(f"LearnedFace.name must be a str or None, got {self.name!r}")
        for attr in ("created_s", "last_seen_s"):
            value = float(getattr(self, attr))
            if not math.isfinite(value):
                raise ValueError(f"LearnedFace.{attr} must be finite")
            setattr(self, attr, value)
        if int(self.n_observations) < 0:
            raise ValueError("LearnedFace.n_observations must be >= 0")
        self.n_observations = int(self.n_observations)


@dataclass
class IdentityStats:
    """Counters for diagnostics (the node publishes/logs them)."""

    steps: int = 0
    observations_received: int = 0
    observations_ignored_dead_track: int = 0
    assigned_known: int = 0
    new_faces: int = 0
    released: int = 0
    sinkhorn_runs: int = 0
    sinkhorn_not_converged: int = 0
    last_sinkhorn_iterations: int = 0
    shortlist_searches: int = 0
    faces_forgotten: int = 0
    observations_not_learned_inconsistent: int = 0


# ----------------------------------------------------------------------------------- pure functions
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


def _pairwise_sq_dists(f: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.floating[Any]]:
    sq = np.einsum("ij,ij->i", f, f)
    d2 = sq[:, None] + sq[None, :] - 2.0 * (f @ f.T)
    np.maximum(d2, 0.0, out=d2)
    np.fill_diagonal(d2, np.inf)
    return d2


def _greedy_keep(d2: npt.NDArray[np.floating[Any]], max_count: int) -> npt.NDArray[np.intp]:
    """Core of :func:`select_diverse_subset` on a squared-distance matrix (diagonal = inf); modifies d2."""
    n = d2.shape[0]
    alive = np.ones(n, dtype=bool)
    for _ in range(n - max_count):
        a, b = divmod(int(np.argmin(d2)), n)
        # nearest neighbour of a and of b, each excluding the other
        d2[a, b] = d2[b, a] = np.inf
        na, nb = float(d2[a].min()), float(d2[b].min())
        drop = a if na < nb else b if nb < na else min(a, b)
        alive[drop] = False
        d2[drop, :] = np.inf
        d2[:, drop] = np.inf
    return np.flatnonzero(alive)


def select_diverse_subset(features: npt.ArrayLike, max_count: int) -> npt.NDArray[np.intp]:
    """Indices (sorted) of at most ``max_count`` rows kept to preserve diversity.

    Greedy: while too many, take the closest pair and drop the member whose nearest *other* neighbour
    is closer (the more redundant one; ties drop the lower index, i.e. the older feature).  This keeps
    the set spread out (max-min style) so a bounded face model still covers all seen views.
    """
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2:
        raise ValueError(f"features must be 2-D, got shape {f.shape}")
    if max_count < 1:
        raise ValueError(f"max_count must be >= 1, got {max_count}")
    if f.shape[0] <= max_count:
        return np.arange(f.shape[0])
    return _greedy_keep(_pairwise_sq_dists(f), max_count)


def min_distances_to_faces(observations: npt.ArrayLike, faces: Iterable[npt.ArrayLike]) -> FloatArray:
    """Reference eq. 4: (Q, M) matrix of min_k ||f_q - f_jk|| in float64 (slow, for tests/checks)."""
    obs = np.asarray(observations, dtype=np.float64)
    cols = []
    for face in faces:
        fj = np.asarray(face, dtype=np.float64)
        cols.append(np.sqrt(((obs[:, None, :] - fj[None, :, :]) ** 2).sum(-1)).min(axis=1))
    return np.stack(cols, axis=1) if cols else np.zeros((obs.shape[0], 0))


# ------------------------------------------------------------------------------------- feature bank
_GEMV_MAX_ROWS = 2
_PAD_SQN = np.float32(1e30)  # squared norm of padding rows: finite (BLAS-safe) but never the minimum


class _FeatureBank:
    """Bounded feature sets of all learned faces in one padded float32 block (slot, k, dim + 1).

    Column ``dim`` holds ||f||^2 (1e30 for padding rows), so one GEMM of the augmented observations
    [-2 q, 1] gives ||f||^2 - 2 q.f for every stored feature: eq. 4 minima without ragged loops.  Each
    slot also caches its features' pairwise squared distances so inserting into a full set (diversity
    pruning) costs O(k^2) instead of recomputing a Gram matrix.
    """

    def __init__(self, dim: int, max_per_face: int) -> None:
        self.dim = dim
        self.kmax = max_per_face
        self.n = 0
        self._free: list[int] = []
        self._alloc(8)

    def _alloc(self, cap: int) -> None:
        old = self.n
        feats = np.zeros((cap, self.kmax, self.dim + 1), dtype=np.float32)
        feats[:, :, self.dim] = _PAD_SQN
        pd2 = np.full((cap, self.kmax, self.kmax), np.inf, dtype=np.float32)
        count = np.zeros(cap, dtype=np.int64)
        cen = np.zeros((cap, self.dim + 1), dtype=np.float32)
        if old:
            feats[:old] = self.feats[:old]
            pd2[:old] = self.pd2[:old]
            count[:old] = self.count[:old]
            cen[:old] = self.centroid[:old]
        self.feats, self.pd2, self.count, self.centroid = feats, pd2, count, cen

    def new_slot(self, features: F32Array) -> int:
        if self._free:
            slot = self._free.pop()
        else:
            if self.n == self.feats.shape[0]:
                self._alloc(self.n + self.n // 2)
            slot = self.n
            self.n += 1
        self.count[slot] = 0
        self.add_features(slot, features)
        return slot

    def free_slot(self, slot: int) -> None:
        """Return a slot (e.g. a dead unassigned track's buffer) for reuse."""
        self.feats[slot, :, : self.dim] = 0.0
        self.feats[slot, :, self.dim] = _PAD_SQN
        self.pd2[slot] = np.inf
        self.count[slot] = 0
        self._free.append(slot)

    def features(self, slot: int) -> F32Array:
        return np.ascontiguousarray(self.feats[slot, : int(self.count[slot]), : self.dim])

    def add_features(self, slot: int, new: F32Array) -> None:
        """Insert features; when more than kmax, keep a diverse subset (:func:`select_diverse_subset`)."""
        m = new.shape[0]
        if m == 0:
            return
        k = int(self.count[slot])
        dim = self.dim
        stored = self.feats[slot, :k, :dim]
        new_sq = np.einsum("ij,ij->i", new, new)
        cross = new_sq[:, None] + self.feats[slot, :k, dim][None, :] - 2.0 * (new @ stored.T)  # (m, k)
        np.maximum(cross, 0.0, out=cross)
        nn = new_sq[:, None] + new_sq[None, :] - 2.0 * (new @ new.T)
        np.maximum(nn, 0.0, out=nn)
        np.fill_diagonal(nn, np.inf)
        if m == 1 and k == self.kmax and k >= 2:
            self._replace_one(slot, new[0], float(new_sq[0]), cross[0])
            return
        if k + m <= self.kmax:
            self.feats[slot, k : k + m, :dim] = new
            self.feats[slot, k : k + m, dim] = new_sq
            self.pd2[slot, k : k + m, :k] = cross
            self.pd2[slot, :k, k : k + m] = cross.T
            self.pd2[slot, k : k + m, k : k + m] = nn
            self.count[slot] = k + m
        else:
            d2 = np.empty((k + m, k + m), dtype=np.float32)
            d2[:k, :k] = self.pd2[slot, :k, :k]
            d2[k:, :k] = cross
            d2[:k, k:] = cross.T
            d2[k:, k:] = nn
            keep = _greedy_keep(d2.copy(), self.kmax)
            allf = np.concatenate([self.feats[slot, :k], np.column_stack([new, new_sq])])
            n_keep = len(keep)
            self.feats[slot, :n_keep] = allf[keep]
            self.feats[slot, n_keep:, :dim] = 0.0
            self.feats[slot, n_keep:, dim] = _PAD_SQN
            self.pd2[slot] = np.inf
            self.pd2[slot, :n_keep, :n_keep] = d2[np.ix_(keep, keep)]
            self.count[slot] = n_keep
        c = self.feats[slot, : int(self.count[slot]), :dim].mean(axis=0)
        self.centroid[slot, :dim] = c
        self.centroid[slot, dim] = float(c @ c)

    def add_one_each(self, slots: npt.NDArray[np.intp], new: F32Array) -> None:
        """One new feature into each of several distinct *full* slots, vectorised across slots.

        Same decisions as :meth:`_replace_one` (hence as :func:`_greedy_keep`), ~30 numpy calls in total
        instead of ~15 per slot: the per-frame cost of all identified tracks' observations.
        """
        t, k, dim = len(slots), self.kmax, self.dim
        rows = np.arange(t)
        x_sq = np.einsum("ij,ij->i", new, new)
        block = self.feats[slots]  # (t, k, dim + 1)
        cross = x_sq[:, None] + block[:, :, dim] - 2.0 * np.einsum("tkd,td->tk", block[:, :, :dim], new)
        np.maximum(cross, 0.0, out=cross)
        pd = self.pd2[slots]  # (t, k, k)
        flat = pd.reshape(t, k * k).argmin(axis=1)
        a, b = np.divmod(flat, k)
        pmin = pd[rows, a, b]
        j = cross.argmin(axis=1)
        pair_with_x = cross[rows, j] < pmin
        # closest pair (j, x): reject x when its other nearest neighbour is closer than j's
        nn_j = pd[rows, j].min(axis=1)
        nn_x = np.partition(cross, 1, axis=1)[:, 1]
        # closest pair (a, b) among stored: nearest other neighbour of each, x included
        pd_a = pd[rows, a].copy()
        pd_a[rows, b] = np.inf
        pd_b = pd[rows, b].copy()
        pd_b[rows, a] = np.inf
        na = np.minimum(pd_a.min(axis=1), cross[rows, a])
        nb = np.minimum(pd_b.min(axis=1), cross[rows, b])
        drop_stored = np.where(na < nb, a, np.where(nb < na, b, np.minimum(a, b)))
        drop = np.where(pair_with_x, j, drop_stored)
        keep_new = ~(pair_with_x & (nn_x < nn_j))
        if not keep_new.any():
            return
        sl, dr, xs, cr = slots[keep_new], drop[keep_new], new[keep_new], cross[keep_new]
        self.centroid[sl, :dim] += (xs - self.feats[sl, dr, :dim]) / k
        cen = self.centroid[sl, :dim]
        self.centroid[sl, dim] = np.einsum("ij,ij->i", cen, cen)
        self.feats[sl, dr, :dim] = xs
        self.feats[sl, dr, dim] = x_sq[keep_new]
        self.pd2[sl, dr, :] = cr
        self.pd2[sl, :, dr] = cr
        self.pd2[sl, dr, dr] = np.inf

    def _replace_one(self, slot: int, x: F32Array, x_sq: float, cross: F32Array) -> None:
        """One new feature into a full set: same rule as :func:`_greedy_keep` for a single removal, but
        without building the (k+1)^2 matrix; either x is rejected or it overwrites the dropped row."""
        k = self.kmax
        pd = self.pd2[slot]
        a, b = divmod(int(np.argmin(pd)), k)
        j = int(np.argmin(cross))
        if cross[j] < pd[a, b]:  # closest pair is (j, x)
            nn_j = float(pd[j].min())
            nn_x = float(np.partition(cross, 1)[1])
            if nn_x < nn_j:  # x is the more redundant one: reject it
                return
            drop = j  # (a tie drops the older feature, as in _greedy_keep)
        else:  # closest pair is (a, b) among the stored features
            ra = pd[a].copy()
            ra[b] = np.inf
            rb = pd[b].copy()
            rb[a] = np.inf
            na = min(float(ra.min()), float(cross[a]))
            nb = min(float(rb.min()), float(cross[b]))
            drop = a if na < nb else b if nb < na else min(a, b)
        c = self.centroid[slot, : self.dim]
        c += (x - self.feats[slot, drop, : self.dim]) / k  # incremental mean (in place)
        self.centroid[slot, self.dim] = float(c @ c)
        self.feats[slot, drop, : self.dim] = x
        self.feats[slot, drop, self.dim] = x_sq
        pd[drop, :] = cross
        pd[:, drop] = cross
        pd[drop, drop] = np.inf

    @staticmethod
    def augment(obs: F32Array) -> F32Array:
        """[-2 q, 1] rows for the augmented GEMM."""
        aug = np.empty((obs.shape[0], obs.shape[1] + 1), dtype=np.float32)
        np.multiply(obs, -2.0, out=aug[:, :-1])
        aug[:, -1] = 1.0
        return aug

    def exact_min_distances(self, obs: F32Array, slots: npt.NDArray[np.intp]) -> FloatArray:
        """(Q, len(slots)) eq. 4 distances: one float32 GEMM, min over each face's rows, + ||q||^2."""
        q = obs.shape[0]
        aug = self.augment(obs)
        if len(slots) * 2 >= self.n:  # most faces: scan the whole bank, then select columns
            n_faces, sel = self.n, slots
            flat = self.feats[: self.n].reshape(self.n * self.kmax, self.dim + 1)
        else:
            n_faces, sel = len(slots), None
            flat = self.feats[slots].reshape(len(slots) * self.kmax, self.dim + 1)
        if q <= _GEMV_MAX_ROWS:  # OpenBLAS: 1-2 matrix-vector products beat a skinny GEMM (measured)
            d2 = np.stack([(flat @ aug[r]).reshape(n_faces, self.kmax).min(axis=1) for r in range(q)])
        else:
            d2 = (flat @ aug.T).reshape(n_faces, self.kmax, q).min(axis=1).T  # streams the bank once
        if sel is not None:
            d2 = d2[:, sel]
        d2 = d2.astype(np.float64) + np.einsum("ij,ij->i", obs, obs).astype(np.float64)[:, None]
        np.maximum(d2, 0.0, out=d2)
        return np.sqrt(d2)

    def shortlist_min_distances(self, obs: F32Array, slots: npt.NDArray[np.intp], size: int) -> FloatArray:
        """Eq. 4 distances to the ``size`` faces with the nearest centroids; +inf for the others."""
        q = obs.shape[0]
        aug = self.augment(obs)
        obs_sq = np.einsum("ij,ij->i", obs, obs).astype(np.float64)
        dc = aug @ self.centroid[slots].T  # ||c||^2 - 2 q.c, same ranking as ||q - c||
        top = np.argpartition(dc, size - 1, axis=1)[:, :size]
        out = np.full((q, len(slots)), np.inf)
        for r in range(q):
            cand = slots[top[r]]
            dmin = (self.feats[cand] @ aug[r]).min(axis=1).astype(np.float64) + obs_sq[r]
            out[r, top[r]] = np.sqrt(np.maximum(dmin, 0.0))
        return out


# ------------------------------------------------------------------------------- identity managers
@dataclass
class _Face:
    face_id: int
    slot: int
    name: str | None
    created_s: float
    last_seen_s: float
    n_observations: int
    track_id: int | None = None  # live track currently carrying this face (None = in face_list)


@dataclass
class _Track:
    track_id: int
    slot: int | None = None  # bank slot buffering observed features while unassigned (track.face_images)
    n_observations: int = 0
    first_seen_s: float = 0.0
    last_seen_s: float = 0.0
    face_id: int | None = None
    confidence: float = 0.0
    votes: list[tuple[int, float]] = field(default_factory=list)  # threshold baseline only


def _check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an int, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def _check_float(name: str, value: Any, low: float, high: float, low_open: bool, high_open: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    v = float(value)
    ok = math.isfinite(v) and (v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not ok:
        lb = "(" if low_open else "["
        rb = ")" if high_open else "]"
        raise ValueError(f"{name} must be in {lb}{low}, {high}{rb}, got {value!r}")
    return v


def _check_stamp(stamp_s: Any) -> float:
    if isinstance(stamp_s, bool) or not isinstance(stamp_s, (int, float, np.floating, np.integer)):
        raise ValueError(f"stamp_s must be a number of seconds, got {stamp_s!r}")
    v = float(stamp_s)
    if not math.isfinite(v):
        raise ValueError(f"stamp_s must be finite, got {stamp_s!r}")
    return v


class IdentityManagerBase:
    """Algorithm 1 of the paper, shared by the Bayesian method and the threshold baseline.

    face_list = learned faces not carried by a live track (assignable); track_list = live tracks.  An
    unassigned track accumulates evidence from its observations; once classified it gets a known face
    (which leaves face_list and absorbs the track's features) or a new face id.  While assigned, further
    observations are added to its face.  When the track dies the face returns to face_list.

    ``embedding_dim``: length of the face descriptors.  ``max_features_per_face``: bound of every face's
    (and unidentified track's) feature set, kept diverse (:func:`select_diverse_subset`).  Eq. 4 is exact
    while face_list holds at most ``exact_search_max_features`` features; beyond, only the
    ``shortlist_faces`` faces with the nearest centroids are compared per observation.  Track ids must not
    be reused after :meth:`track_deleted` (late observations of a deleted id are ignored).

    ``feature_gate_distance`` (None = the paper: every observation of an identified track joins its face):
    an observation farther than this from every feature of the track's face is not learned (counted in
    ``stats.observations_not_learned_inconsistent``).  When the tracker swaps two people, the face then
    does not absorb the other person's features, which would make that person's later tracks look like
    this face.
    """

    _DEAD_TRACK_MEMORY = 4096  # ids of deleted tracks remembered to ignore late observations

    def __init__(
        self,
        *,
        embedding_dim: int = 128,
        max_features_per_face: int = 50,
        exact_search_max_features: int = 20_000,
        shortlist_faces: int = 32,
        feature_gate_distance: float | None = None,
    ) -> None:
        self.embedding_dim = _check_int("embedding_dim", embedding_dim, 1)
        if feature_gate_distance is not None:
            feature_gate_distance = _check_float(
                "feature_gate_distance", feature_gate_distance, 0.0, math.inf, True, True
            )
        self.feature_gate_distance = feature_gate_distance
        self.max_features_per_face = _check_int("max_features_per_face", max_features_per_face, 1)
        self.exact_search_max_features = _check_int("exact_search_max_features", exact_search_max_features, 0)
        self.shortlist_faces = _check_int("shortlist_faces", shortlist_faces, 1)
        self._bank = _FeatureBank(self.embedding_dim, self.max_features_per_face)
        self._faces: dict[int, _Face] = {}
        self._tracks: dict[int, _Track] = {}
        self._available: list[int] = []  # face_list in column order (Bayes: table columns 1..M)
        self._available_slots = np.zeros(0, dtype=np.intp)
        self._pending_obs: dict[int, list[F32Array]] = {}
        self._pending_deleted: dict[int, float] = {}
        self._dead: OrderedDict[int, float] = OrderedDict()
        self._next_face_id = 1
        self.stats = IdentityStats()

    # ------------------------------------------------------------------------------ public inputs
    def add_observations(self, track_id: int, embeddings: npt.ArrayLike, stamp_s: float) -> bool:
        """Queue face embeddings (K, embedding_dim) observed on a track; used at the next :meth:`step`.

        Returns False (and counts it) when the track was already deleted (a late message).
        Raises ValueError on a wrong shape/dtype, NaN or Inf.
        """
        tid = _check_int("track_id", track_id, -(2**63))
        stamp = _check_stamp(stamp_s)
        emb = np.asarray(embeddings)
        if emb.ndim != 2 or emb.shape[1] != self.embedding_dim:
            raise ValueError(
                f"embeddings must have shape (K, {self.embedding_dim}), got {emb.shape} for track {tid}"
            )
        if not (np.issubdtype(emb.dtype, np.floating) or np.issubdtype(emb.dtype, np.integer)) or (
            emb.dtype == np.bool_
        ):
            raise ValueError(f"embeddings must be a real numeric array, got dtype {emb.dtype}")
        if not np.all(np.isfinite(emb)):
            raise ValueError(f"embeddings of track {tid} contain NaN or Inf")
        if emb.shape[0] == 0:
            return True
        if tid in self._dead or tid in self._pending_deleted:
            self.stats.observations_ignored_dead_track += emb.shape[0]
            return False
        self._pending_obs.setdefault(tid, []).append(np.ascontiguousarray(emb, dtype=np.float32))
        self.stats.observations_received += emb.shape[0]
        track = self._tracks.get(tid)
        if track is not None:
            track.last_seen_s = max(track.last_seen_s, stamp)
        else:
            self._tracks[tid] = _Track(tid, None, 0, stamp, stamp)
        return True

    def track_deleted(self, track_id: int, stamp_s: float) -> None:
        """The tracker dropped this track; handled at the next :meth:`step` (after its last evidence)."""
        tid = _check_int("track_id", track_id, -(2**63))
        stamp = _check_stamp(stamp_s)
        if tid in self._dead:
            return
        self._pending_deleted[tid] = stamp

    def sync_alive_tracks(self, alive_track_ids: Iterable[int], stamp_s: float) -> None:
        """Mark every known track not in ``alive_track_ids`` as deleted (OpenPTrack's garbage collection)."""
        alive = {_check_int("track_id", t, -(2**63)) for t in alive_track_ids}
        for tid in list(self._tracks):
            if tid not in alive:
                self.track_deleted(tid, stamp_s)

    def step(self, stamp_s: float) -> list[IdentityEvent]:
        """Run one update of Algorithm 1: ingest queued observations, classify, then handle deaths."""
        stamp = _check_stamp(stamp_s)
        self.stats.steps += 1
        events: list[IdentityEvent] = []
        pending = self._pending_obs
        self._pending_obs = {}
        unassigned_ids: list[int] = []
        unassigned_obs: list[F32Array] = []
        bank = self._bank
        single_slots: list[int] = []  # one new feature into a full feature set: batched below
        single_obs: list[F32Array] = []
        for tid, chunks in pending.items():
            obs = chunks[0] if len(chunks) == 1 else np.concatenate(chunks)
            track = self._tracks[tid]
            track.n_observations += obs.shape[0]
            if track.face_id is not None:
                face = self._faces[track.face_id]
                slot: int | None = face.slot
                face.n_observations += obs.shape[0]
                face.last_seen_s = max(face.last_seen_s, stamp)
                if self.feature_gate_distance is not None:
                    obs = self._consistent(obs, face.slot)
                    if obs.shape[0] == 0:
                        continue
            else:
                slot = track.slot
                if slot is None:
                    track.slot = bank.new_slot(obs)
                unassigned_ids.append(tid)
                unassigned_obs.append(obs)
            if slot is not None:
                if obs.shape[0] == 1 and bank.count[slot] == bank.kmax >= 2:
                    single_slots.append(slot)
                    single_obs.append(obs)
                else:
                    bank.add_features(slot, obs)
        if single_slots:
            bank.add_one_each(np.array(single_slots, dtype=np.intp), np.concatenate(single_obs))
        if unassigned_ids:
            self._ingest_unassigned(unassigned_ids, unassigned_obs)
        for tid, face_or_new, confidence in self._decide():
            events.append(self._apply_decision(tid, face_or_new, confidence, stamp))
        for tid in list(self._pending_deleted):
            ev = self._remove_track(tid, self._pending_deleted[tid])
            if ev is not None:
                events.append(ev)
        self._pending_deleted.clear()
        return events

    def _consistent(self, obs: F32Array, slot: int) -> F32Array:
        """The observations within ``feature_gate_distance`` of a stored feature of the face in ``slot``."""
        assert self.feature_gate_distance is not None
        d = self._bank.exact_min_distances(obs, np.array([slot], dtype=np.intp))[:, 0]
        keep = d <= self.feature_gate_distance
        self.stats.observations_not_learned_inconsistent += int(keep.size - np.count_nonzero(keep))
        return obs if keep.all() else obs[keep]

    # ------------------------------------------------------------------------------ queries
    def face_id_of(self, track_id: int) -> int | None:
        """Face id assigned to a live track, or None while unidentified / unknown track."""
        track = self._tracks.get(track_id)
        return None if track is None else track.face_id

    def confidence_of(self, track_id: int) -> float:
        """Current max posterior (Bayes) / leading vote fraction of an unassigned track; the decision
        confidence once assigned; 0.0 for an unknown track."""
        track = self._tracks.get(track_id)
        if track is None:
            return 0.0
        if track.face_id is not None:
            return track.confidence
        return self._current_confidence(track)

    def posterior_of(self, track_id: int) -> dict[int, float]:
        """Hypotheses of an unassigned track: {0: new person, face_id: probability}; {} if none."""
        return {}

    def assigned_tracks(self) -> dict[int, int]:
        """Live track id -> face id for all identified tracks."""
        return {t.track_id: t.face_id for t in self._tracks.values() if t.face_id is not None}

    def live_track_ids(self) -> list[int]:
        """Tracks that have reported observations and are not deleted."""
        return list(self._tracks)

    def face_ids(self) -> list[int]:
        """All learned face ids (assigned or in face_list)."""
        return sorted(self._faces)

    def available_face_ids(self) -> list[int]:
        """face_list: learned faces not carried by a live track, in table-column order."""
        return list(self._available)

    def face_features(self, face_id: int) -> F32Array:
        """Copy of a learned face's stored features (k, embedding_dim)."""
        return self._bank.features(self._face(face_id).slot).copy()

    def face_name(self, face_id: int) -> str | None:
        return self._face(face_id).name

    def set_face_name(self, face_id: int, name: str | None) -> None:
        """Attach a (predefined-person) name to a learned face, or clear it with None."""
        if name is not None and not isinstance(name, str):
            raise ValueError(f"name must be a str or None, got {name!r}")
        self._face(face_id).name = name

    def forget_face(self, face_id: int) -> bool:
        """Remove a learned face entirely (privacy: "delete this person"); False if the id is unknown.

        The face leaves face_list (its table column / threshold votes go) and its bank slot is zeroed.
        If a live track carries it, that track becomes unidentified again: its assignment, confidence
        and queued observations are dropped (they were merged into / meant for the forgotten face), so
        while the person stays in view new observations are classified afresh and normally create a
        *new* face id after ``min_observations``.  Face ids are never reused within this manager.
        """
        fid = _check_int("face_id", face_id, -(2**63))
        face = self._faces.get(fid)
        if face is None:
            return False
        if face.track_id is None:
            self._make_unavailable([fid])
        else:
            track = self._tracks.get(face.track_id)
            if track is not None and track.face_id == fid:
                track.face_id = None
                track.confidence = 0.0
                track.n_observations = 0
                track.votes.clear()
                self._pending_obs.pop(track.track_id, None)
        self._bank.free_slot(face.slot)
        del self._faces[fid]
        self.stats.faces_forgotten += 1
        return True

    def export_face(self, face_id: int) -> LearnedFace:
        """Snapshot (copy) of one learned face, e.g. to save it when its track is released; KeyError if unknown."""
        f = self._face(face_id)
        return LearnedFace(
            f.face_id, self._bank.features(f.slot).copy(), f.name, f.created_s, f.last_seen_s, f.n_observations
        )

    def export_faces(self) -> list[LearnedFace]:
        """Snapshot of all learned faces (copies), for the persistent memory."""
        return [self.export_face(fid) for fid in sorted(self._faces)]

    def reserve_face_ids(self, highest_used_id: int) -> None:
        """Never hand out face ids <= ``highest_used_id`` (ids of forgotten faces stay retired)."""
        self._next_face_id = max(self._next_face_id, _check_int("highest_used_id", highest_used_id, 0) + 1)

    def import_faces(self, faces: Iterable[LearnedFace]) -> None:
        """Add previously exported faces to face_list; ValueError on an id clash or wrong dimension."""
        batch = list(faces)
        seen: set[int] = set()
        for f in batch:
            if not isinstance(f, LearnedFace):
                raise ValueError(f"import_faces expects LearnedFace records, got {type(f).__name__}")
            if f.features.shape[1] != self.embedding_dim:
                raise ValueError(
                    f"face {f.face_id}: features have dim {f.features.shape[1]}, "
                    f"expected {self.embedding_dim}"
                )
            if f.face_id in self._faces or f.face_id in seen:
                raise ValueError(f"face id {f.face_id} already exists")
            seen.add(f.face_id)
        for f in batch:
            slot = self._bank.new_slot(f.features)
            self._faces[f.face_id] = _Face(
                f.face_id, slot, f.name, f.created_s, f.last_seen_s, f.n_observations
            )
            self._next_face_id = max(self._next_face_id, f.face_id + 1)
            self._make_available(f.face_id)

    # ------------------------------------------------------------------------------ internals
    def _face(self, face_id: int) -> _Face:
        face = self._faces.get(face_id)
        if face is None:
            raise KeyError(f"unknown face id {face_id}")
        return face

    def _available_distances(self, obs: F32Array) -> FloatArray:
        """Eq. 4 distances (Q, M) from observations to every face in face_list (column order)."""
        slots = self._available_slots
        if len(slots) == 0:
            return np.zeros((obs.shape[0], 0))
        n_feats = int(self._bank.count[slots].sum())
        if n_feats > self.exact_search_max_features and len(slots) > self.shortlist_faces:
            self.stats.shortlist_searches += 1
            return self._bank.shortlist_min_distances(obs, slots, self.shortlist_faces)
        return self._bank.exact_min_distances(obs, slots)

    def _make_available(self, face_id: int) -> None:
        self._faces[face_id].track_id = None
        self._available.append(face_id)
        self._available_slots = np.append(self._available_slots, self._faces[face_id].slot).astype(np.intp)
        self._on_face_available(face_id)

    def _make_unavailable(self, face_ids: list[int]) -> None:
        idx = [self._available.index(f) for f in face_ids]
        keep = np.ones(len(self._available), dtype=bool)
        keep[idx] = False
        self._on_faces_unavailable(idx)
        self._available = [f for f, k in zip(self._available, keep, strict=True) if k]
        self._available_slots = self._available_slots[keep]

    def _apply_decision(self, tid: int, face_or_new: int, confidence: float, stamp: float) -> IdentityEvent:
        track = self._tracks[tid]
        assert track.slot is not None, "a track is only classified after observations"
        if face_or_new == 0:
            fid = self._next_face_id
            self._next_face_id += 1
            slot = track.slot  # the track's buffer becomes the new face's feature set
            self._faces[fid] = _Face(fid, slot, None, stamp, stamp, track.n_observations, tid)
            kind = IdentityEventKind.NEW_FACE
            self.stats.new_faces += 1
        else:
            fid = face_or_new
            face = self._faces[fid]
            self._make_unavailable([fid])
            self._bank.add_features(face.slot, self._bank.features(track.slot))  # add result.face_images
            self._bank.free_slot(track.slot)
            face.track_id = tid
            face.n_observations += track.n_observations
            face.last_seen_s = max(face.last_seen_s, stamp)
            kind = IdentityEventKind.ASSIGNED_KNOWN
            self.stats.assigned_known += 1
        self._on_track_identified(tid)
        self._faces[fid].track_id = tid
        track.face_id = fid
        track.confidence = float(confidence)
        track.slot = None
        track.votes.clear()
        return IdentityEvent(kind, tid, fid, stamp, float(confidence))

    def _remove_track(self, tid: int, stamp: float) -> IdentityEvent | None:
        self._dead[tid] = stamp
        while len(self._dead) > self._DEAD_TRACK_MEMORY:
            self._dead.popitem(last=False)
        self._pending_obs.pop(tid, None)
        track = self._tracks.pop(tid, None)
        if track is None:
            return None
        if track.face_id is None:
            if track.slot is not None:
                self._bank.free_slot(track.slot)
            self._on_track_forgotten(tid)
            return None
        self._make_available(track.face_id)
        self.stats.released += 1
        return IdentityEvent(IdentityEventKind.RELEASED, tid, track.face_id, stamp, track.confidence)

    # hooks for the classification method
    def _ingest_unassigned(self, track_ids: list[int], observations: list[F32Array]) -> None:
        raise NotImplementedError

    def _decide(self) -> list[tuple[int, int, float]]:
        raise NotImplementedError

    def _current_confidence(self, track: _Track) -> float:
        raise NotImplementedError

    def _on_face_available(self, face_id: int) -> None:
        """A face joined face_list (appended as the last column)."""

    def _on_faces_unavailable(self, column_indices: list[int]) -> None:
        """Faces at these 0-based positions of face_list are leaving it."""

    def _on_track_identified(self, track_id: int) -> None:
        """An unassigned track got a face id (its table row goes away)."""

    def _on_track_forgotten(self, track_id: int) -> None:
        """An unassigned track died."""


class FaceIdentityManager(IdentityManagerBase):
    """Algorithm 1 with the paper's Bayesian face classification (posterior table + Sinkhorn).

    Parameters (OpenPTrack's values in brackets): ``prior_probability`` of new table cells [0.1],
    ``posterior_threshold`` to decide [0.95], ``min_observations`` compared with the decided column [3],
    ``clamp_probability`` applied after normalisation [1e-3], ``sinkhorn_tolerance`` on row sums [1e-3]
    and ``sinkhorn_max_iterations`` [10]; ``sinkhorn_solver`` "newton" (same fixed point in a few
    iterations) or "sinkhorn" (the paper's alternations).  ``max_abs_log_likelihood_ratio`` (None = the
    paper) optionally bounds the evidence of a single observation, against wrong crops / track swaps.
    The remaining arguments are those of :class:`IdentityManagerBase`.
    """

    def __init__(
        self,
        likelihood: LikelihoodModel | None = None,
        *,
        prior_probability: float = 0.1,
        posterior_threshold: float = 0.95,
        min_observations: int = 3,
        clamp_probability: float = 1e-3,
        sinkhorn_tolerance: float = 1e-6,
        sinkhorn_max_iterations: int = 100,
        sinkhorn_solver: str = "newton",
        max_abs_log_likelihood_ratio: float | None = None,
        embedding_dim: int = 128,
        max_features_per_face: int = 50,
        exact_search_max_features: int = 20_000,
        shortlist_faces: int = 32,
        feature_gate_distance: float | None = None,
    ) -> None:
        super().__init__(
            embedding_dim=embedding_dim,
            max_features_per_face=max_features_per_face,
            exact_search_max_features=exact_search_max_features,
            shortlist_faces=shortlist_faces,
            feature_gate_distance=feature_gate_distance,
        )
        if likelihood is None:
            likelihood = LikelihoodModel.default()
        if not isinstance(likelihood, LikelihoodModel):
            raise ValueError(f"likelihood must be a LikelihoodModel, got {type(likelihood).__name__}")
        self.likelihood = likelihood
        self.prior_probability = _check_float("prior_probability", prior_probability, 0.0, 1.0, True, True)
        self.clamp_probability = _check_float("clamp_probability", clamp_probability, 0.0, 0.5, False, True)
        self.posterior_threshold = _check_float(
            "posterior_threshold", posterior_threshold, 0.5, 1.0 - self.clamp_probability, True, True
        )
        self.min_observations = _check_int("min_observations", min_observations, 1)
        self.sinkhorn_tolerance = _check_float("sinkhorn_tolerance", sinkhorn_tolerance, 0.0, 1.0, True, True)
        self.sinkhorn_max_iterations = _check_int("sinkhorn_max_iterations", sinkhorn_max_iterations, 1)
        if sinkhorn_solver not in ("newton", "sinkhorn"):
            raise ValueError(f"sinkhorn_solver must be 'newton' or 'sinkhorn', got {sinkhorn_solver!r}")
        self.sinkhorn_solver = sinkhorn_solver
        if max_abs_log_likelihood_ratio is not None:
            max_abs_log_likelihood_ratio = _check_float(
                "max_abs_log_likelihood_ratio", max_abs_log_likelihood_ratio, 0.0, math.inf, True, True
            )
        self.max_abs_log_likelihood_ratio = max_abs_log_likelihood_ratio
        self._log_c = math.log(self.likelihood.new_person_scale_c)
        self._table = np.zeros((1, 1))  # row 0 / column 0 slack; P[0, 0] unused (0)
        self._counts = np.zeros((1, 1), dtype=np.int64)
        self._rows: list[int] = []  # track ids of rows 1..N
        self._row_of: dict[int, int] = {}
        self._dirty = False
        self._converged = True

    # ------------------------------------------------------------------------------ queries
    def posterior_table(self) -> tuple[FloatArray, list[int], list[int]]:
        """(copy of the table, track ids of rows 1..N, face ids of columns 1..M)."""
        return self._table.copy(), list(self._rows), list(self._available)

    @property
    def is_normalised(self) -> bool:
        """True when the stored table is the (clamped) result of a converged Sinkhorn normalisation."""
        return not self._dirty and self._converged

    def observation_counts(self) -> npt.NDArray[np.int64]:
        """Copy of the per-cell observation counts (same layout as the table)."""
        return self._counts.copy()

    def posterior_of(self, track_id: int) -> dict[int, float]:
        row = self._row_of.get(track_id)
        if row is None:
            return {}
        p = self._table[row]
        out = {0: float(p[0])}
        out.update({fid: float(v) for fid, v in zip(self._available, p[1:], strict=True)})
        return out

    def _current_confidence(self, track: _Track) -> float:
        row = self._row_of.get(track.track_id)
        return 0.0 if row is None else float(self._table[row].max())

    # ------------------------------------------------------------------------------ table structure
    def _reindex_rows(self) -> None:
        self._row_of = {tid: i + 1 for i, tid in enumerate(self._rows)}

    def _add_row(self, track_id: int) -> None:
        m1 = self._table.shape[1]
        self._table = np.vstack([self._table, np.full((1, m1), self.prior_probability)])
        self._counts = np.vstack([self._counts, np.zeros((1, m1), dtype=np.int64)])
        self._rows.append(track_id)
        self._row_of[track_id] = len(self._rows)
        self._dirty = True

    def _remove_rows(self, track_ids: list[int]) -> None:
        idx = [self._row_of[t] for t in track_ids if t in self._row_of]
        if not idx:
            return
        self._table = np.delete(self._table, idx, axis=0)
        self._counts = np.delete(self._counts, idx, axis=0)
        drop = set(track_ids)
        self._rows = [t for t in self._rows if t not in drop]
        self._reindex_rows()
        self._dirty = True

    def _on_face_available(self, face_id: int) -> None:
        n1 = self._table.shape[0]
        self._table = np.hstack([self._table, np.full((n1, 1), self.prior_probability)])
        self._counts = np.hstack([self._counts, np.zeros((n1, 1), dtype=np.int64)])
        self._dirty = True

    def _on_faces_unavailable(self, column_indices: list[int]) -> None:
        cols = [c + 1 for c in column_indices]
        self._table = np.delete(self._table, cols, axis=1)
        self._counts = np.delete(self._counts, cols, axis=1)
        self._dirty = True

    def _on_track_identified(self, track_id: int) -> None:
        self._remove_rows([track_id])

    def _on_track_forgotten(self, track_id: int) -> None:
        self._remove_rows([track_id])

    # ------------------------------------------------------------------------------ inference
    def _ingest_unassigned(self, track_ids: list[int], observations: list[F32Array]) -> None:
        for tid in track_ids:
            if tid not in self._row_of:
                self._add_row(tid)
        obs = np.concatenate(observations) if len(observations) > 1 else observations[0]
        sizes = np.array([o.shape[0] for o in observations])
        rows = np.array([self._row_of[t] for t in track_ids])
        m = len(self._available)
        log_ev = np.empty((len(track_ids), m + 1))
        log_ev[:, 0] = sizes * self._log_c  # column 0: c per observation (ratio form, see module doc)
        if m:
            d = self._available_distances(obs)
            n_feats = self._bank.count[self._available_slots].astype(np.float64)[None, :]  # K of eq. 4
            finite = np.isfinite(d)
            if finite.all():
                lr = self.likelihood._log_ratio_unchecked(d, n_feats)
            else:  # faces outside the search shortlist: the weakest evidence (distance d_hi or more)
                far = self.likelihood._log_ratio_unchecked(np.full(m, np.inf), n_feats[0])
                lr = np.repeat(far[None, :], d.shape[0], axis=0)
                lr[finite] = self.likelihood._log_ratio_unchecked(
                    d[finite], np.broadcast_to(n_feats, d.shape)[finite]
                )
            if self.max_abs_log_likelihood_ratio is not None:
                np.clip(lr, -self.max_abs_log_likelihood_ratio, self.max_abs_log_likelihood_ratio, out=lr)
            if len(sizes) == obs.shape[0]:
                log_ev[:, 1:] = lr
            else:
                starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
                log_ev[:, 1:] = np.add.reduceat(lr, starts, axis=0)
        log_ev -= log_ev.max(axis=1, keepdims=True)  # per-row rescale: exact after row normalisation
        self._table[rows] *= np.exp(log_ev)
        self._counts[rows] += sizes[:, None]
        self._dirty = True

    def _normalise(self) -> None:
        if len(self._rows) == 0:
            self._dirty = False
            self._converged = True
            return
        res = sinkhorn_with_slack(
            self._table, self.sinkhorn_tolerance, self.sinkhorn_max_iterations, self.sinkhorn_solver
        )
        self.stats.sinkhorn_runs += 1
        self.stats.last_sinkhorn_iterations = res.iterations
        self._converged = res.converged
        if not res.converged:
            self.stats.sinkhorn_not_converged += 1
        table = np.clip(res.table, self.clamp_probability, 1.0 - self.clamp_probability)
        table[0, 0] = 0.0
        self._table = table
        self._dirty = False

    def _decide(self) -> list[tuple[int, int, float]]:
        if self._dirty:
            self._normalise()
        if not self._rows:
            return []
        body = self._table[1:]
        best = np.argmax(body, axis=1)
        idx = np.arange(len(self._rows))
        p = body[idx, best]
        n_obs = self._counts[1:][idx, best]
        ok = np.flatnonzero((p > self.posterior_threshold) & (n_obs >= self.min_observations))
        decisions = []
        for r in ok:
            col = int(best[r])
            face = 0 if col == 0 else self._available[col - 1]
            decisions.append((self._rows[r], face, float(p[r])))
        return decisions


class ThresholdIdentityManager(IdentityManagerBase):
    """The paper's baseline: per observation, nearest learned face if its eq. 4 distance is below
    ``distance_threshold`` else "new"; decide by majority after ``n_votes`` observations.

    Ties: a face beats "new" only with strictly more votes; among faces the smaller mean distance wins.
    """

    def __init__(
        self,
        *,
        distance_threshold: float = 0.6,
        n_votes: int = 5,
        embedding_dim: int = 128,
        max_features_per_face: int = 50,
        exact_search_max_features: int = 20_000,
        shortlist_faces: int = 32,
        feature_gate_distance: float | None = None,
    ) -> None:
        super().__init__(
            embedding_dim=embedding_dim,
            max_features_per_face=max_features_per_face,
            exact_search_max_features=exact_search_max_features,
            shortlist_faces=shortlist_faces,
            feature_gate_distance=feature_gate_distance,
        )
        self.distance_threshold = _check_float(
            "distance_threshold", distance_threshold, 0.0, math.inf, True, True
        )
        self.n_votes = _check_int("n_votes", n_votes, 1)

    def _ingest_unassigned(self, track_ids: list[int], observations: list[F32Array]) -> None:
        obs = np.concatenate(observations) if len(observations) > 1 else observations[0]
        d = self._available_distances(obs)
        if d.shape[1]:
            j = np.argmin(d, axis=1)
            dmin = d[np.arange(d.shape[0]), j]
        else:
            j = np.zeros(obs.shape[0], dtype=np.intp)
            dmin = np.full(obs.shape[0], np.inf)
        pos = 0
        for tid, o in zip(track_ids, observations, strict=True):
            votes = self._tracks[tid].votes
            for r in range(pos, pos + o.shape[0]):
                if dmin[r] < self.distance_threshold:
                    votes.append((self._available[int(j[r])], float(dmin[r])))
                else:
                    votes.append((0, float(dmin[r])))
            pos += o.shape[0]

    def _tally(self, track: _Track) -> tuple[int, float]:
        """(winner: face id or 0 = new, vote fraction) over votes for faces still in face_list."""
        available = set(self._available)
        counts: dict[int, list[float]] = {}
        for fid, dist in track.votes:
            if fid == 0 or fid in available:
                counts.setdefault(fid, []).append(dist)
        if not counts:
            return 0, 0.0
        total = sum(len(v) for v in counts.values())
        faces = [(-len(v), float(np.mean(v)), fid) for fid, v in counts.items() if fid != 0]
        n_new = len(counts.get(0, []))
        if faces:
            neg_n, _, fid = min(faces)
            if -neg_n > n_new:
                return fid, -neg_n / total
        return 0, n_new / total

    def _current_confidence(self, track: _Track) -> float:
        return self._tally(track)[1]

    def _decide(self) -> list[tuple[int, int, float]]:
        decisions = []
        taken: set[int] = set()
        for track in self._tracks.values():
            if track.face_id is not None or len(track.votes) < self.n_votes:
                continue
            track.votes = [v for v in track.votes if v[0] not in taken]
            winner, frac = self._tally(track)
            if winner != 0:
                taken.add(winner)
            decisions.append((track.track_id, winner, frac))
        return decisions

    def _make_unavailable(self, face_ids: list[int]) -> None:
        super()._make_unavailable(face_ids)
        gone = set(face_ids)
        for track in self._tracks.values():
            if track.face_id is None and track.votes:
                track.votes = [v for v in track.votes if v[0] not in gone]


def make_identity_manager(method: str = "bayes", **params: Any) -> IdentityManagerBase:
    """Factory for the node: ``method="bayes"`` (paper) or ``"threshold"`` (baseline)."""
    if method == "bayes":
        return FaceIdentityManager(**params)
    if method == "threshold":
        return ThresholdIdentityManager(**params)
    raise ValueError(f"method must be 'bayes' or 'threshold', got {method!r}")
