"""XQDA (Liao et al., CVPR 2015): a discriminant subspace and a Mahalanobis metric learned together.

W holds the directions where different people's differences spread most relative to one person's: the
leading generalised eigenvectors of (Sigma_E, Sigma_I), i.e. of Sigma_I^-1 Sigma_E (second seed, eq. 4).
In that subspace M = Sigma_I'^-1 - Sigma_E'^-1 with Sigma' = W^T Sigma W, the log-likelihood ratio of
"different" against "same" for zero-mean Gaussian differences. Closed form: no optimisation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import scipy.linalg

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.body.linear_metric import LinearMetric
from face_reid_master.training.body.pair_covariance import PairCovariances, pair_covariances

__all__ = ["fit_xqda", "xqda_for_dims", "xqda_from_covariances"]


def fit_xqda(features: npt.ArrayLike, labels: npt.ArrayLike, *, regularisation: float = 1e-3,
             max_dims: int | None = None) -> LinearMetric:
    """XQDA on ``features`` (n, d) with person ``labels``.

    ``regularisation``: added to Sigma_I's diagonal (relative to its mean variance; Liao et al. use 1e-3)
    so that few samples in many dimensions still give an invertible matrix. ``max_dims``: most subspace
    dimensions kept (None: all whose eigenvalue exceeds 1, the directions where different people differ
    more than one person does; at least one).
    """
    return xqda_from_covariances(pair_covariances(features, labels), regularisation=regularisation,
                                 max_dims=max_dims)


def xqda_from_covariances(cov: PairCovariances, *, regularisation: float = 1e-3,
                          max_dims: int | None = None) -> LinearMetric:
    """:func:`fit_xqda` from the pair covariances (e.g. a :meth:`PairCovariances.subset` of features)."""
    return xqda_for_dims(cov, regularisation=regularisation, max_dims=(max_dims,))[0]


def xqda_for_dims(cov: PairCovariances, *, regularisation: float,
                  max_dims: Sequence[int | None]) -> list[LinearMetric]:
    """One XQDA metric per subspace cap in ``max_dims`` (None: no cap), from one eigen-decomposition."""
    reg = check_real("regularisation", regularisation, 0.0, 1e6)
    d = cov.intra.shape[0]
    caps = [None if m is None else check_int("max_dims", m, 1, d) for m in max_dims]
    if not caps:
        raise ValueError("max_dims must hold at least one cap (None = no cap)")
    intra = cov.intra + reg * max(float(np.trace(cov.intra)) / d, 1e-12) * np.eye(d)
    values, vectors = scipy.linalg.eigh(cov.extra, intra)  # ascending; vectors^T intra vectors = I
    order = np.argsort(values)[::-1]
    values, vectors = values[order], vectors[:, order]
    above = max(1, int(np.count_nonzero(values > 1.0)))
    out = []
    for cap in caps:
        r = above if cap is None else min(above, cap)
        w = vectors[:, :r]
        metric = np.linalg.inv(w.T @ intra @ w) - np.linalg.inv(w.T @ cov.extra @ w)
        out.append(LinearMetric(w, metric, "xqda", {
            "eigenvalues": values[:r].tolist(), "regularisation": reg, "max_dims": cap,
            "n_intra_pairs": cov.n_intra_pairs, "n_extra_pairs": cov.n_extra_pairs}))
    return out
