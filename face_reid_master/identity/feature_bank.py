"""Bounded, diverse per-face feature sets and their eq. 4 distances (Koide et al. 2017, III-D).

Eq. 4: the distance of an observation to a face is the minimum over that face's stored features.
:class:`FeatureBank` computes it for all faces with one float32 GEMM; :func:`min_distances_to_faces`
is the slow float64 reference.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["FeatureBank", "min_distances_to_faces", "select_diverse_subset"]

FloatArray = npt.NDArray[np.float64]
F32Array = npt.NDArray[np.float32]


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



_GEMV_MAX_ROWS = 2
_PAD_SQN = np.float32(1e30)  # squared norm of padding rows: finite (BLAS-safe) but never the minimum
_FIRST_WIDTH = 8  # feature rows per slot allocated at first (doubled when a slot needs more, up to kmax)


class FeatureBank:
    """Bounded feature sets of all faces (and unidentified tracks) in one padded float32 block (slot, width,
    dim + 1), ``width`` the largest set stored rounded up to a power of two (at most ``kmax``): 2000 faces of 8
    features take 8 rows each, not the bound's 50.

    Column ``dim`` holds ||f||^2 (1e30 for padding rows), so one GEMM of the augmented observations
    [-2 q, 1] gives ||f||^2 - 2 q.f for every stored feature: eq. 4 minima without ragged loops.  Each
    slot also caches its features' pairwise squared distances so inserting into a full set (diversity
    pruning) costs O(k^2) instead of recomputing a Gram matrix.
    """

    def __init__(self, dim: int, max_per_face: int) -> None:
        """``dim``: embedding length; ``max_per_face``: the bound k of every slot's feature set."""
        self.dim = dim
        self.kmax = max_per_face
        self.width = min(_FIRST_WIDTH, max_per_face)  # feature rows allocated per slot: grows to kmax on demand
        self.n = 0
        self._free: list[int] = []
        self._alloc(8)

    def _alloc(self, cap: int, width: int | None = None) -> None:
        """(Re)allocate the block for ``cap`` slots of ``width`` rows each, keeping what is stored."""
        old, old_width = self.n, self.width
        width = old_width if width is None else width
        feats = np.zeros((cap, width, self.dim + 1), dtype=np.float32)
        feats[:, :, self.dim] = _PAD_SQN
        pd2 = np.full((cap, width, width), np.inf, dtype=np.float32)
        count = np.zeros(cap, dtype=np.int64)
        cen = np.zeros((cap, self.dim + 1), dtype=np.float32)
        if old:
            feats[:old, :old_width] = self.feats[:old]
            pd2[:old, :old_width, :old_width] = self.pd2[:old]
            count[:old] = self.count[:old]
            cen[:old] = self.centroid[:old]
        self.feats, self.pd2, self.count, self.centroid = feats, pd2, count, cen
        self.width = width

    def _fit(self, rows: int) -> None:
        """Widen every slot (doubling, at most kmax) so that one can hold ``rows`` features: memory follows the
        largest feature set stored, not the bound."""
        if rows > self.width:
            width = self.width
            while width < rows:
                width *= 2
            self._alloc(self.feats.shape[0], min(width, self.kmax))

    @property
    def nbytes(self) -> int:
        """Bytes of the bank's arrays (memory measurements)."""
        return int(self.feats.nbytes + self.pd2.nbytes + self.count.nbytes + self.centroid.nbytes)

    def new_slot(self, features: F32Array) -> int:
        """A slot (reused or new, the block grows by half) holding ``features``; returns its index."""
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
        """The stored features of a slot (k, dim), without the norm column."""
        return np.ascontiguousarray(self.feats[slot, : int(self.count[slot]), : self.dim])

    def add_features(self, slot: int, new: F32Array) -> None:
        """Insert features; when more than kmax, keep a diverse subset (:func:`select_diverse_subset`)."""
        m = new.shape[0]
        if m == 0:
            return
        k = int(self.count[slot])
        self._fit(min(k + m, self.kmax))
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
            keep = _greedy_keep(d2.copy(), self.kmax)  # (the block is kmax wide: _fit above)
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
            flat = self.feats[: self.n].reshape(self.n * self.width, self.dim + 1)
        else:
            n_faces, sel = len(slots), None
            flat = self.feats[slots].reshape(len(slots) * self.width, self.dim + 1)
        if q <= _GEMV_MAX_ROWS:  # OpenBLAS: 1-2 matrix-vector products beat a skinny GEMM (measured)
            d2 = np.stack([(flat @ aug[r]).reshape(n_faces, self.width).min(axis=1) for r in range(q)])
        else:
            d2 = (flat @ aug.T).reshape(n_faces, self.width, q).min(axis=1).T  # streams the bank once
        if sel is not None:
            d2 = d2[:, sel]
        d2 = d2.astype(np.float64) + np.einsum("ij,ij->i", obs, obs).astype(np.float64)[:, None]
        np.maximum(d2, 0.0, out=d2)
        return np.sqrt(d2)

    def own_min_distances(self, obs: F32Array, slots: npt.NDArray[np.intp]) -> FloatArray:
        """(Q,) eq. 4 distance of each observation to the face in its own slot ``slots[q]``: one batched product
        for all identified tracks' observations of a step (instead of one GEMM per track)."""
        if not obs.shape[0]:
            return np.zeros(0)
        d2 = np.einsum("qkd,qd->qk", self.feats[slots], self.augment(obs)).min(axis=1).astype(np.float64)
        d2 += np.einsum("ij,ij->i", obs, obs).astype(np.float64)
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

