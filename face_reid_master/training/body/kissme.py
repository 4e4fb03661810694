"""KISSME (Koestinger et al., CVPR 2012): M = Sigma_I^-1 - Sigma_E^-1, made positive semi-definite.

The log-likelihood ratio of zero-mean Gaussian differences, like XQDA but in a fixed space: the raw
features or their leading principal components (``pca_dims``), chosen before and apart from the metric.
The comparison for XQDA in the second seed.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.body.linear_metric import LinearMetric
from face_reid_master.training.body.pair_covariance import PairCovariances, pair_covariances

__all__ = ["fit_kissme", "kissme_from_covariances"]


def fit_kissme(features: npt.ArrayLike, labels: npt.ArrayLike, *, regularisation: float = 1e-3,
               pca_dims: int | None = None) -> LinearMetric:
    """KISSME on ``features`` (n, d) with person ``labels``; ``pca_dims`` principal components first
    (None: the raw features); ``regularisation`` as for :func:`~face_reid_master.training.body.xqda.fit_xqda`,
    on both covariances. Negative eigenvalues of M are clipped to 0 (a metric, not just a ratio)."""
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"features must be (n, d), got {x.shape}")
    if pca_dims is None:
        return kissme_from_covariances(pair_covariances(x, labels), regularisation=regularisation)
    pca_dims = check_int("pca_dims", pca_dims, 1, min(x.shape[1], max(1, x.shape[0] - 1)))
    _, _, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    w = vt[:pca_dims].T
    inner = kissme_from_covariances(pair_covariances(x @ w, labels), regularisation=regularisation)
    return LinearMetric(w, inner.metric, "kissme", {**inner.info, "pca_dims": pca_dims})


def kissme_from_covariances(cov: PairCovariances, *, regularisation: float = 1e-3) -> LinearMetric:
    """KISSME in the covariances' own space (W = I), e.g. of a :meth:`PairCovariances.subset` of features."""
    reg = check_real("regularisation", regularisation, 0.0, 1e6)
    r = cov.intra.shape[0]

    def regularised(c: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return c + reg * max(float(np.trace(c)) / r, 1e-12) * np.eye(r)

    m = np.linalg.inv(regularised(cov.intra)) - np.linalg.inv(regularised(cov.extra))
    values, vectors = np.linalg.eigh(0.5 * (m + m.T))
    m = (vectors * np.maximum(values, 0.0)) @ vectors.T
    return LinearMetric(np.eye(r), m, "kissme", {"regularisation": reg, "pca_dims": None,
                                                 "clipped_eigenvalues": int(np.count_nonzero(values < 0))})
