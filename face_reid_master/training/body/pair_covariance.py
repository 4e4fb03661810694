"""Covariances of same-person and different-person feature differences, from class sums (no pair loop).

Metric learning from pairs (KISSME, XQDA) needs the covariance of x_i - x_j over all pairs of samples of
one person (Sigma_I) and of two different people (Sigma_E). Summed over all ordered pairs of a set with
sum s and scatter S = sum x x^T, the differences give 2 n S - 2 s s^T; per class the same with the
class's n_k, s_k, S_k. So both covariances cost O(n d^2), whatever the number of pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["PairCovariances", "pair_covariances"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PairCovariances:
    """Sigma_I / Sigma_E (d x d) and how many ordered pairs each averages."""

    intra: FloatArray
    extra: FloatArray
    n_intra_pairs: int
    n_extra_pairs: int

    def subset(self, index: npt.ArrayLike) -> PairCovariances:
        """The covariances of the features ``index`` only (a difference's coordinates are the features'):
        candidate feature sets are scored without recomputing the pair sums."""
        i = np.asarray(index, dtype=np.intp).reshape(-1)
        d = self.intra.shape[0]
        if i.size == 0 or i.min() < 0 or i.max() >= d:
            raise ValueError(f"index must select features in [0, {d}), got {i.tolist()}")
        grid = np.ix_(i, i)
        return PairCovariances(self.intra[grid], self.extra[grid], self.n_intra_pairs, self.n_extra_pairs)


def _pair_scatter(n: float, s: FloatArray, scatter: FloatArray) -> FloatArray:
    """Sum over all ordered pairs (i, j) of a set of (x_i - x_j)(x_i - x_j)^T."""
    return 2.0 * n * scatter - 2.0 * np.outer(s, s)


def pair_covariances(features: npt.ArrayLike, labels: npt.ArrayLike) -> PairCovariances:
    """Sigma_I and Sigma_E of ``features`` (n, d) with one person label per row (ValueError if a kind of
    pair is missing: a person with two samples and two people are needed)."""
    x = np.asarray(features, dtype=np.float64)
    y = np.asarray(labels)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"features must be (n >= 2, d), got {x.shape}")
    if y.shape != (x.shape[0],):
        raise ValueError(f"labels must have one value per feature row ({x.shape[0]}), got {y.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("features contain NaN or Inf")
    _, inverse, counts = np.unique(y, return_inverse=True, return_counts=True)
    n_classes = counts.size
    sums = np.zeros((n_classes, x.shape[1]))
    np.add.at(sums, inverse, x)
    total_scatter = x.T @ x
    total = _pair_scatter(float(x.shape[0]), x.sum(axis=0), total_scatter)
    # per class: 2 n_k S_k - 2 s_k s_k^T, summed; sum_k n_k S_k = X^T diag(n_{label}) X
    weighted = (x * counts[inverse][:, None]).T @ x
    intra_sum = 2.0 * weighted - 2.0 * sums.T @ sums
    n_intra = int(np.sum(counts * (counts - 1)))
    n_extra = int(x.shape[0] ** 2 - np.sum(counts**2))
    if n_intra == 0:
        raise ValueError("no person has two samples: the same-person covariance is undefined")
    if n_extra == 0:
        raise ValueError("all samples are of one person: the different-person covariance is undefined")
    return PairCovariances(intra_sum / n_intra, (total - intra_sum) / n_extra, n_intra, n_extra)
