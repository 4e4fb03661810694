"""A Mahalanobis distance in a linear subspace: d(x, y)^2 = (W^T (x - y))^T M (W^T (x - y)).

Euclidean (W = I, M = I), KISSME and XQDA all come out in this form, so evaluation and fusion treat them
alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = ["LinearMetric", "euclidean_metric"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LinearMetric:
    """``projection`` W (d, r) and ``metric`` M (r, r, symmetric positive semi-definite); ``name`` for reports."""

    projection: FloatArray
    metric: FloatArray
    name: str = "mahalanobis"
    info: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        w, m = np.asarray(self.projection, dtype=np.float64), np.asarray(self.metric, dtype=np.float64)
        if w.ndim != 2 or m.shape != (w.shape[1], w.shape[1]):
            raise ValueError(f"projection must be (d, r) and metric (r, r), got {w.shape} and {m.shape}")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(m))):
            raise ValueError("projection / metric contain NaN or Inf")
        object.__setattr__(self, "projection", w)
        object.__setattr__(self, "metric", 0.5 * (m + m.T))

    @property
    def input_dim(self) -> int:
        return int(self.projection.shape[0])

    def project(self, features: npt.ArrayLike) -> FloatArray:
        """Features (n, d) in the metric's subspace (n, r)."""
        x = np.asarray(features, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.input_dim:
            raise ValueError(f"features must be (n, {self.input_dim}), got {x.shape}")
        return x @ self.projection

    def distances(self, a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
        """Distances (na, nb) between the rows of ``a`` and of ``b`` (one GEMM in the subspace)."""
        pa, pb = self.project(a), self.project(b)
        ma, mb = pa @ self.metric, pb @ self.metric
        d2 = np.einsum("ij,ij->i", ma, pa)[:, None] + np.einsum("ij,ij->i", mb, pb)[None, :] - 2.0 * ma @ pb.T
        return np.sqrt(np.maximum(d2, 0.0))


def euclidean_metric(dim: int) -> LinearMetric:
    """The plain L2 distance on ``dim`` features (the baseline)."""
    return LinearMetric(np.eye(dim), np.eye(dim), "euclidean")
