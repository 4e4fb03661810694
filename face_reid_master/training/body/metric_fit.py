"""Fit what a body metric file holds: per feature XQDA on the wire vectors, its distance unit, N_p / N_n on
held-out distances and the decision distance.

The likelihoods must describe distances of people the metric has not learned (the master meets new
people), so they are fitted on cross-fitted distances: per fold of the identities, XQDA is fitted on the
other folds and measures the pairs within the fold. Each metric's distances are divided by its median
different-person distance on its own training crops, so the shipped metric and the fold metrics share a
unit (1 = a typical stranger).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int
from face_reid_master.body.features import METRIC_FEATURES, feature_columns
from face_reid_master.body.linear_metric import LinearMetric
from face_reid_master.body.metric_file import BodyFeatureMetric
from face_reid_master.identity.likelihood import LikelihoodModel, fit_skewnormal
from face_reid_master.training.body.model_selection import Choice
from face_reid_master.training.body.xqda import fit_xqda

__all__ = ["FeatureFit", "fit_feature_metrics", "pair_distances"]


@dataclass(frozen=True)
class FeatureFit:
    """A fitted feature metric and the held-out same-person (``positive``) / different-person (``negative``)
    pair distances its likelihoods were fitted on."""

    metric: BodyFeatureMetric
    positive: npt.NDArray[np.float64]
    negative: npt.NDArray[np.float64]


def pair_distances(distances: npt.ArrayLike, labels: npt.ArrayLike, groups: npt.ArrayLike,
                   max_negative_pairs: int, rng: np.random.Generator
                   ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(positive, negative) entries of a square distance matrix: every pair (i < j) of one label, and at most
    ``max_negative_pairs`` pairs of two labels within one group (uniform sample, without replacement)."""
    d = np.asarray(distances, dtype=np.float64)
    y, g = np.asarray(labels), np.asarray(groups)
    if d.ndim != 2 or d.shape[0] != d.shape[1] or y.shape != (d.shape[0],) or g.shape != y.shape:
        raise ValueError(f"distances must be square with one label and group per row, got {d.shape}, {y.shape}, "
                         f"{g.shape}")
    check_int("max_negative_pairs", max_negative_pairs, 1)
    iu, ju = np.triu_indices(y.size, k=1)
    same = y[iu] == y[ju]
    neg = np.flatnonzero(~same & (g[iu] == g[ju]))
    if neg.size > max_negative_pairs:
        neg = np.sort(rng.choice(neg, size=max_negative_pairs, replace=False))
    return d[iu[same], ju[same]], d[iu[neg], ju[neg]]


def _unit(metric: LinearMetric, x: npt.NDArray[np.float64], labels: npt.NDArray[Any], groups: npt.NDArray[Any],
          max_pairs: int, rng: np.random.Generator) -> LinearMetric:
    """``metric`` scaled so that its median different-person distance on ``x`` is 1."""
    _, neg = pair_distances(metric.distances(x, x), labels, groups, max_pairs, rng)
    if not neg.size:
        raise ValueError("no different-person pair within a group: cannot set the distance unit")
    scale = float(np.median(neg))
    if scale <= 0.0:
        raise ValueError("the median different-person distance is 0: the features do not separate people")
    return LinearMetric(metric.projection, metric.metric / scale**2, metric.name,
                        {**metric.info, "distance_scale": scale})


def _fit_one(x: npt.NDArray[np.float64], labels: npt.NDArray[Any], groups: npt.NDArray[Any], choice: Choice,
             max_pairs: int, rng: np.random.Generator) -> LinearMetric:
    metric = fit_xqda(x, labels, regularisation=choice.regularisation,
                      max_dims=None if choice.max_dims is None else min(choice.max_dims, x.shape[1]))
    return _unit(metric, x, labels, groups, max_pairs, rng)


def fit_feature_metrics(wire: npt.ArrayLike, labels: npt.ArrayLike, groups: npt.ArrayLike,
                        slices: Mapping[str, slice], choices: Mapping[str, Choice],
                        folds: Sequence[npt.NDArray[np.bool_]], max_negative_pairs: int,
                        rng: np.random.Generator) -> dict[str, FeatureFit]:
    """Per feature of ``METRIC_FEATURES``: XQDA with ``choices[feature]`` on the ``wire`` vectors (n, length) of
    people ``labels``, in distance units, with skew-normal N_p / N_n fitted on the held-out distances of the
    ``folds`` (masks over the rows, e.g. :func:`~face_reid_master.training.body.model_selection.identity_folds`).
    Different-person pairs are taken within a ``groups`` value only (e.g. one source data set: people of one
    site are what a master compares), at most ``max_negative_pairs`` per fold and for the unit."""
    v = np.asarray(wire, dtype=np.float64)
    y, g = np.asarray(labels), np.asarray(groups)
    if v.ndim != 2 or y.shape != (v.shape[0],) or g.shape != y.shape:
        raise ValueError(f"wire must be (n, length) with one label and group per row, got {v.shape}, {y.shape}, "
                         f"{g.shape}")
    if not folds or any(np.asarray(m).shape != y.shape for m in folds):
        raise ValueError(f"folds must be at least one mask of {y.size} rows")
    out = {}
    for name in METRIC_FEATURES:
        cols = feature_columns(slices, name)
        x = v[:, cols]
        choice = choices[name]
        metric = _fit_one(x, y, g, choice, max_negative_pairs, rng)
        positive, negative = [], []
        for held in folds:
            held = np.asarray(held, dtype=bool)
            fold_metric = _fit_one(x[~held], y[~held], g[~held], choice, max_negative_pairs, rng)
            p, n = pair_distances(fold_metric.distances(x[held], x[held]), y[held], g[held], max_negative_pairs, rng)
            positive.append(p)
            negative.append(n)
        pos, neg = np.concatenate(positive), np.concatenate(negative)
        likelihood = LikelihoodModel(fit_skewnormal(pos), fit_skewnormal(neg))
        parameters = {"regularisation": choice.regularisation, "max_dims": choice.max_dims,
                      "subspace_dims": int(metric.projection.shape[1]),
                      "distance_scale": metric.info["distance_scale"],
                      "held_out_pairs": {"positive": int(pos.size), "negative": int(neg.size)},
                      "cv_rank1": round(choice.rank1, 4), "cv_map": round(choice.mean_average_precision, 4)}
        out[name] = FeatureFit(BodyFeatureMetric(name, cols, metric, likelihood, parameters), pos, neg)
    return out
