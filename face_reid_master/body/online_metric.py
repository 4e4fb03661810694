"""Online body-metric update from face-verified pairs (second seed, Algorithm 1: P-N learning).

The shipped XQDA metric was learned offline on other people in other light. While the master runs, faces
settle who is who; body pairs whose metric ranking disagrees with the faces (a person's own earlier body
ranked below E other people: an *error positive*; another person's body ranked within the first E: an
*error negative*) are kept and XQDA is re-fitted with them.

The re-fit stays in the offline metric's own subspace z = W^T x, where XQDA left the offline covariances
as Sigma_I = I and Sigma_E = (I - s^2 M)^-1 (s: its distance unit). The offline metric counts as
``prior_pairs`` pairs of each kind; the mined pairs' difference covariances are added to it; XQDA's closed
form gives the new M (the prior's I is the offline regularisation too), rescaled so that a typical
stranger stays at the same distance (tr(M Sigma_E) kept).
Because W stays, an embedding of the old metric maps to the new one by one (r, r) matrix
(:func:`embedding_change`): galleries are converted, never recomputed from descriptors.

A wrong face decision can add at most ``max_pairs_per_track`` pairs: every pair names the two tracks it
came from and a track takes part in at most that many (a swapped track's pairs are removed).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.body.linear_metric import LinearMetric
from face_reid_master.body.metric_file import BodyFeatureMetric

__all__ = ["MinedPair", "OnlineBodyMetric", "PairPool", "embedding_change", "refit_metric", "subspace_key",
           "subspace_prior", "to_subspace"]

FloatArray = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]


def subspace_prior(base: BodyFeatureMetric) -> FloatArray:
    """Sigma_E of the offline XQDA in its subspace (Sigma_I there is I): (I - s^2 M)^-1 with s the metric's
    ``distance_scale`` (ValueError for a metric that is not an XQDA with a distance unit)."""
    scale = base.parameters.get("distance_scale")
    if base.metric.name != "xqda" or not isinstance(scale, (int, float)) or not scale > 0:
        raise ValueError(f"the online update needs an XQDA metric with a distance_scale parameter; feature "
                         f"{base.name} is {base.metric.name!r} with distance_scale {scale!r}")
    r = base.metric.metric.shape[0]
    inner = np.eye(r) - float(scale) ** 2 * base.metric.metric
    values = np.linalg.eigvalsh(0.5 * (inner + inner.T))
    if values.min() <= 0.0:
        raise ValueError(f"feature {base.name}: I - s^2 M is not positive definite (min eigenvalue "
                         f"{values.min():.3g}): not the XQDA form the online update assumes")
    sigma_e = np.linalg.inv(inner)
    return 0.5 * (sigma_e + sigma_e.T)


def subspace_key(feature: BodyFeatureMetric) -> str:
    """Names the subspace of a metric (its W): saved pairs are differences there and only valid with it."""
    w = np.ascontiguousarray(feature.metric.projection, dtype="<f8")
    return f"{feature.name}:{w.shape[0]}x{w.shape[1]}:{hashlib.sha256(w.tobytes()).hexdigest()[:16]}"


def to_subspace(feature: BodyFeatureMetric, embeddings: npt.ArrayLike) -> FloatArray:
    """Embedding rows of ``feature`` (e = z L) back in the subspace z (needs a full-rank metric)."""
    e = np.atleast_2d(np.asarray(embeddings, dtype=np.float64))
    return np.linalg.solve(feature.embedding_factor.T, e.T).T


def embedding_change(old: BodyFeatureMetric, new: BodyFeatureMetric) -> F32:
    """(r, r) R with new.embed(x) = old.embed(x) @ R, for two metrics of one subspace W."""
    if old.metric.projection.shape != new.metric.projection.shape or \
            not np.array_equal(old.metric.projection, new.metric.projection):
        raise ValueError("the two metrics do not share their subspace: embeddings cannot be converted")
    return np.linalg.solve(old.embedding_factor, new.embedding_factor).astype(np.float32)


def refit_metric(base: BodyFeatureMetric, positive: npt.ArrayLike, negative: npt.ArrayLike, *,
                 prior_pairs: float, floor: float = 1e-4) -> BodyFeatureMetric:
    """XQDA of ``base`` re-fitted with mined subspace differences ``positive`` (n_p, r, same person) and
    ``negative`` (n_n, r, different people); the offline metric weighs as ``prior_pairs`` pairs of each kind.
    Directions XQDA would drop keep ``floor`` x the largest metric weight (the metric stays full rank, so
    embeddings keep converting). Same likelihoods, same distance unit (tr(M Sigma_E) of ``base`` kept)."""
    check_real("prior_pairs", prior_pairs, 0.0, math.inf, low_open=True)
    r = base.metric.metric.shape[0]
    pos = np.asarray(positive, dtype=np.float64).reshape(-1, r)
    neg = np.asarray(negative, dtype=np.float64).reshape(-1, r)
    sigma_e0 = subspace_prior(base)
    intra = (prior_pairs * np.eye(r) + pos.T @ pos) / (prior_pairs + pos.shape[0])
    extra = (prior_pairs * sigma_e0 + neg.T @ neg) / (prior_pairs + neg.shape[0])
    # generalised eigenproblem extra v = lambda intra v through intra's Cholesky factor
    chol = np.linalg.cholesky(intra)
    inv_chol = np.linalg.inv(chol)
    values, u = np.linalg.eigh(inv_chol @ extra @ inv_chol.T)
    vectors = inv_chol.T @ u  # vectors^T intra vectors = I
    weights = 1.0 - 1.0 / np.maximum(values, 1e-12)  # M = V diag(1 - 1/lambda) V^T in XQDA's closed form
    weights = np.maximum(weights, floor * max(float(weights.max()), 1e-12))
    metric = (vectors * weights) @ vectors.T
    metric = 0.5 * (metric + metric.T)
    metric *= float(np.trace(base.metric.metric @ extra)) / float(np.trace(metric @ extra))
    parameters = {**base.parameters, "online_pairs": {"positive": int(pos.shape[0]), "negative": int(neg.shape[0])},
                  "online_prior_pairs": float(prior_pairs)}
    return BodyFeatureMetric(base.name, base.columns, LinearMetric(base.metric.projection, metric, "xqda"),
                             base.likelihood, parameters)


@dataclass(frozen=True)
class MinedPair:
    """A body pair the faces labelled: the difference of the two embeddings (current metric), whether the
    two are one person, their faces and the tracks they came from."""

    difference: F32
    positive: bool
    face_a: int
    face_b: int
    track_a: int
    track_b: int
    stamp_s: float


class PairPool:
    """The mined pairs (subspace differences), at most ``capacity`` (the oldest go first), each track in at
    most ``max_pairs_per_track`` of them while it lives (track ids < 0: no live track, e.g. restored pairs)."""

    def __init__(self, dim: int, *, capacity: int = 2000, max_pairs_per_track: int = 8) -> None:
        self.dim = check_int("dim", dim, 1)
        self.capacity = check_int("capacity", capacity, 1)
        self.max_pairs_per_track = check_int("max_pairs_per_track", max_pairs_per_track, 1)
        self.vectors = np.zeros((self.capacity, self.dim), np.float32)
        self.positive = np.zeros(self.capacity, bool)
        self.faces = np.zeros((self.capacity, 2), np.int64)
        self.tracks = np.zeros((self.capacity, 2), np.int64)
        self.stamps = np.zeros(self.capacity)
        self.count = 0
        self.version = 0  # bumped by every change
        self.removals = 0  # pairs removed because their face was forgotten or their track released
        self._per_track: dict[int, int] = {}

    def room_for(self, track_a: int, track_b: int) -> bool:
        """Whether both tracks may still take part in a pair."""
        cap = self.max_pairs_per_track
        return all(t < 0 or self._per_track.get(t, 0) < cap for t in (track_a, track_b))

    def add(self, z: npt.ArrayLike, positive: bool, faces: tuple[int, int], tracks: tuple[int, int],
            stamp_s: float) -> bool:
        """Keep one subspace difference; False (nothing kept) when a track has had its share or it is not
        finite."""
        row = np.asarray(z, dtype=np.float32).reshape(-1)
        if row.size != self.dim or not np.isfinite(row).all() or not self.room_for(*tracks):
            return False
        if self.count == self.capacity:  # drop the oldest
            self._remove(np.array([int(np.argmin(self.stamps[: self.count]))]))
        i = self.count
        self.vectors[i], self.positive[i] = row, bool(positive)
        self.faces[i], self.tracks[i], self.stamps[i] = faces, tracks, stamp_s
        self.count += 1
        for t in set(tracks):
            if t >= 0:
                self._per_track[t] = self._per_track.get(t, 0) + 1
        self.version += 1
        return True

    def _remove(self, index: npt.NDArray[np.intp]) -> int:
        if index.size == 0:
            return 0
        keep = np.ones(self.count, bool)
        keep[index] = False
        n = int(keep.sum())
        for name in ("vectors", "positive", "faces", "tracks", "stamps"):
            arr = getattr(self, name)
            arr[:n] = arr[: self.count][keep]
        self.count = n
        self.version += 1
        return int(index.size)

    def remove_face(self, face_id: int) -> int:
        """Drop every pair of a face (the person was forgotten): how many."""
        n = self._remove(np.flatnonzero((self.faces[: self.count] == face_id).any(axis=1)))
        self.removals += n
        return n

    def remove_track(self, track_id: int) -> int:
        """Drop every pair a track took part in (its face decision was wrong): how many."""
        n = self._remove(np.flatnonzero((self.tracks[: self.count] == track_id).any(axis=1)))
        self.removals += n
        return n

    def track_ended(self, track_id: int) -> None:
        """A deleted track adds no more pairs: its count is no longer needed (ids are not reused)."""
        self._per_track.pop(track_id, None)

    def split(self) -> tuple[F32, F32]:
        """Copies of the (positive, negative) differences."""
        v, p = self.vectors[: self.count], self.positive[: self.count]
        return v[p].copy(), v[~p].copy()

    def rows(self) -> list[tuple[F32, bool, int, int, float]]:
        """(difference, positive, face a, face b, stamp) of every pair (to persist them)."""
        return [(self.vectors[i].copy(), bool(self.positive[i]), int(self.faces[i, 0]), int(self.faces[i, 1]),
                 float(self.stamps[i])) for i in range(self.count)]


@dataclass
class _Job:
    future: Future[tuple[BodyFeatureMetric, F32, object]]
    version: int
    removals: int


class OnlineBodyMetric:
    """The body metric in use, the mined pairs and their re-fit (see the module doc).

    ``base``: the offline fused metric. ``prior_pairs``: weight of the offline metric in pairs.
    ``min_new_pairs``: pairs added since the last re-fit before another. ``interval_s``: least time between
    two re-fits (s). ``background``: re-fit (and convert what ``prepare`` returns) on a worker thread and
    install at a later :meth:`poll`, never waiting for it (False: at once, in the caller: deterministic, for
    evaluation). ``capacity`` / ``max_pairs_per_track``: see :class:`PairPool`.
    """

    def __init__(self, base: BodyFeatureMetric, *, prior_pairs: float = 1000.0, min_new_pairs: int = 10,
                 interval_s: float = 30.0, background: bool = True, capacity: int = 2000,
                 max_pairs_per_track: int = 8) -> None:
        subspace_prior(base)  # ValueError early for a metric the update cannot handle
        self.base = base
        self.current = base
        self.prior_pairs = check_real("prior_pairs", prior_pairs, 0.0, math.inf, low_open=True)
        self.min_new_pairs = check_int("min_new_pairs", min_new_pairs, 1)
        self.interval_s = check_real("interval_s", interval_s, 0.0)
        self.background = bool(background)
        self.pool = PairPool(base.metric.metric.shape[0], capacity=capacity, max_pairs_per_track=max_pairs_per_track)
        self.refits = 0
        self.pairs_mined = {"positive": 0, "negative": 0}
        self.pairs_refused = 0  # a track had had its share
        self.refit_failures = 0  # re-fits that failed (the metric in use stays); last_error says why
        self.last_error = ""
        self._fitted_version = 0
        self._fitted_removals = 0
        self._last_refit_s = -math.inf
        self._job: _Job | None = None
        self._executor: ThreadPoolExecutor | None = None

    # ------------------------------------------------------------------ pairs
    def add(self, pairs: Sequence[MinedPair]) -> int:
        """Keep mined pairs (differences of the current metric's embeddings): how many were kept."""
        if not pairs:
            return 0
        z = to_subspace(self.current, np.stack([p.difference for p in pairs]))
        kept = 0
        for row, p in zip(z, pairs, strict=True):
            if self.pool.add(row, p.positive, (p.face_a, p.face_b), (p.track_a, p.track_b), p.stamp_s):
                kept += 1
                self.pairs_mined["positive" if p.positive else "negative"] += 1
            else:
                self.pairs_refused += 1
        return kept

    def room_for(self, track_a: int, track_b: int) -> bool:
        return self.pool.room_for(track_a, track_b)

    def restore(self, rows: Sequence[tuple[npt.ArrayLike, bool, int, int, float]]) -> int:
        """Pairs saved by an earlier run (subspace differences from :meth:`PairPool.rows`), then one re-fit
        at once: how many were restored (rows of another length are skipped)."""
        n = 0
        for z, positive, fa, fb, stamp in rows:
            z = np.asarray(z, dtype=np.float32).reshape(-1)
            if z.size == self.pool.dim and np.isfinite(z).all():
                n += int(self.pool.add(z, positive, (fa, fb), (-1, -1), stamp))  # no live tracks
        if n:
            self.current = self._refit(*self.pool.split())
            self._fitted_version, self._fitted_removals = self.pool.version, self.pool.removals
            self.refits += 1
        return n

    # ------------------------------------------------------------------ re-fit
    def _refit(self, positive: F32, negative: F32) -> BodyFeatureMetric:
        return refit_metric(self.base, positive, negative, prior_pairs=self.prior_pairs)

    def due(self, now_s: float) -> bool:
        """Enough new pairs (or a removal: a forgotten person's pairs must leave the metric) and time since
        the last re-fit, and none running."""
        changed = self.pool.version - self._fitted_version >= self.min_new_pairs \
            or self.pool.removals != self._fitted_removals
        return self._job is None and changed and now_s - self._last_refit_s >= self.interval_s

    def poll(self, now_s: float, prepare: Callable[[], object] | None = None,
             convert: Callable[[object, F32], object] | None = None
             ) -> tuple[BodyFeatureMetric, F32, object] | None:
        """Start a re-fit when one is due, and return a finished one: (new metric, R, converted) where R maps
        old embeddings to new (rows @ R) and ``converted`` is ``convert(prepare(), R)`` computed with it
        (e.g. galleries converted off the frame's thread); None while nothing new is ready. The caller
        installs it (the metric becomes :attr:`current` here)."""
        done = None
        if self._job is not None and self._job.future.done():
            job, self._job = self._job, None
            try:
                new, change, converted = job.future.result()
            except (ValueError, np.linalg.LinAlgError) as exc:  # a degenerate pair set: keep the metric in use
                self._fitted_version, self._fitted_removals = job.version, job.removals
                self._failed(exc)
            else:
                self._fitted_version, self._fitted_removals = job.version, job.removals
                self.current = new
                self.refits += 1
                done = (new, change, converted)
        if done is None and self.due(now_s):  # (not in the poll that installed one: the costs fall apart)
            self._last_refit_s = now_s
            positive, negative = self.pool.split()
            snapshot = prepare() if prepare is not None else None
            old = self.current

            def work() -> tuple[BodyFeatureMetric, F32, object]:
                new = self._refit(positive, negative)
                change = embedding_change(old, new)
                return new, change, convert(snapshot, change) if convert is not None else None

            version, removals = self.pool.version, self.pool.removals
            if self.background:
                if self._executor is None:
                    self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="body-metric-refit")
                self._job = _Job(self._executor.submit(work), version, removals)
            else:
                try:
                    new, change, converted = work()
                except (ValueError, np.linalg.LinAlgError) as exc:
                    self._fitted_version, self._fitted_removals = version, removals
                    self._failed(exc)
                else:
                    self._fitted_version, self._fitted_removals = version, removals
                    self.current = new
                    self.refits += 1
                    done = (new, change, converted)
        return done

    def _failed(self, exc: Exception) -> None:
        self.refit_failures += 1
        self.last_error = f"{type(exc).__name__}: {exc}"[:200]

    def close(self) -> None:
        """Stop the worker (a running re-fit is abandoned)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
