"""Hyper-parameters of the body metrics chosen by cross-validation over identities, never on test people.

K folds partition the identities; per fold the metrics are fitted on the other folds' crops and scored on
this fold's: every crop is a probe against the fold's other crops seen by another camera (every other crop
when a camera is unknown); rank-1, then mAP, averaged over the folds, ranks the candidates. A crop whose person
no other camera saw is no probe, and a fold without any probe is left out (both counted). Candidates:
the principal components kept per block (the leading columns of PCA scores: nested, so one PCA serves
all), the regularisation, and XQDA's subspace cap r. The pair covariances are computed once per fold; a
candidate set of columns takes their sub-matrix.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import product
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.body.projection import FEATURES
from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.body.features import FUSED, METRIC_FEATURES
from face_reid_master.body.linear_metric import LinearMetric
from face_reid_master.training.body.cmc import rank_scores
from face_reid_master.training.body.crops import camera_mask
from face_reid_master.training.body.kissme import kissme_from_covariances
from face_reid_master.training.body.pair_covariance import pair_covariances
from face_reid_master.training.body.xqda import xqda_for_dims

__all__ = ["DEFAULT_MAX_LENGTH", "Choice", "NoCrossCameraMatch", "SearchGrid", "Selection", "dims_candidates",
           "identity_folds", "select_parameters"]

DEFAULT_DIM_STEPS = (16, 32, 48, 64, 80, 96, 112)  # components per block tried
DEFAULT_MAX_LENGTH = 128  # most values per person on the wire (all blocks): 512 bytes of float32
DEFAULT_REGULARISATIONS = (1e-3, 1e-2, 1e-1)  # relative to the mean variance (Liao et al.: 1e-3)
DEFAULT_SUBSPACE_DIMS: tuple[int | None, ...] = (16, 32, 64, None)  # XQDA's r cap (None: every eigenvalue > 1)


def dims_candidates(steps: Sequence[int] = DEFAULT_DIM_STEPS,
                    max_length: int = DEFAULT_MAX_LENGTH) -> tuple[tuple[int, ...], ...]:
    """Every (hsv, siltp) pair of ``steps`` whose sum fits ``max_length`` wire values, smallest first."""
    max_length = check_int("max_length", max_length, 2)
    values = sorted({check_int("dims step", s, 1) for s in steps})
    pairs = tuple(p for p in product(values, repeat=len(FEATURES)) if sum(p) <= max_length)
    if not pairs:
        raise ValueError(f"no (hsv, siltp) pair of steps {values} fits max_length {max_length}")
    return pairs


@dataclass(frozen=True)
class SearchGrid:
    """The candidates: ``pca_dims`` (components per block, in ``FEATURES`` order), ``regularisations`` (of
    KISSME and XQDA) and ``subspace_dims`` (XQDA's r cap; None = no cap)."""

    pca_dims: tuple[tuple[int, ...], ...]
    regularisations: tuple[float, ...] = DEFAULT_REGULARISATIONS
    subspace_dims: tuple[int | None, ...] = DEFAULT_SUBSPACE_DIMS

    def __post_init__(self) -> None:
        dims = tuple(tuple(check_int("pca_dims", v, 1) for v in pair) for pair in self.pca_dims)
        if not dims or any(len(pair) != len(FEATURES) for pair in dims):
            raise ValueError(f"pca_dims must hold at least one ({', '.join(FEATURES)}) tuple, got {self.pca_dims!r}")
        regs = tuple(check_real("regularisations", r, 0.0, 1e6) for r in self.regularisations)
        caps = tuple(None if c is None else check_int("subspace_dims", c, 1) for c in self.subspace_dims)
        if not regs or not caps:
            raise ValueError("regularisations and subspace_dims need at least one value each")
        object.__setattr__(self, "pca_dims", dims)
        object.__setattr__(self, "regularisations", regs)
        object.__setattr__(self, "subspace_dims", caps)

    def capped(self, n_samples: int) -> SearchGrid:
        """This grid with at most the ``n_samples - 1`` components a PCA of ``n_samples`` crops gives."""
        n = check_int("n_samples", n_samples, 2)
        pairs = tuple(dict.fromkeys(tuple(min(d, n - 1) for d in p) for p in self.pca_dims))
        return SearchGrid(pairs, self.regularisations, self.subspace_dims)

    def max_dims(self) -> dict[str, int]:
        """The most components of each block any candidate uses."""
        return {b: max(pair[i] for pair in self.pca_dims) for i, b in enumerate(FEATURES)}

    def to_dict(self) -> dict[str, Any]:
        return {"pca_dims": [dict(zip(FEATURES, p, strict=True)) for p in self.pca_dims],
                "regularisations": list(self.regularisations), "subspace_dims": list(self.subspace_dims)}


class NoCrossCameraMatch(ValueError):
    """No fold holds a person seen by two cameras: the candidates cannot be scored."""


@dataclass(frozen=True)
class Choice:
    """A metric's chosen regularisation and XQDA cap (None for KISSME / no cap) with its cross-validated scores."""

    regularisation: float
    max_dims: int | None
    rank1: float
    mean_average_precision: float

    def to_dict(self) -> dict[str, Any]:
        return {"regularisation": self.regularisation, "max_dims": self.max_dims, "cv_rank1": round(self.rank1, 4),
                "cv_map": round(self.mean_average_precision, 4)}


@dataclass(frozen=True)
class Selection:
    """Chosen components per block (by the fused XQDA), and per feature of ``METRIC_FEATURES`` the XQDA and
    KISSME parameters at those components; ``fused_by_dims`` = the best fused XQDA rank-1 of each candidate;
    ``folds_skipped`` = why each left-out fold was; ``probes`` / ``probes_without_match`` = crops scored / not
    (no crop of their person by another camera)."""

    pca_dims: dict[str, int]
    xqda: dict[str, Choice]
    kissme: dict[str, Choice]
    folds: int
    fused_by_dims: dict[str, float]
    folds_skipped: tuple[str, ...] = ()
    probes: int = 0
    probes_without_match: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {"pca_dims": dict(self.pca_dims), "xqda": {k: v.to_dict() for k, v in self.xqda.items()},
                "kissme": {k: v.to_dict() for k, v in self.kissme.items()}, "folds": self.folds,
                "fused_xqda_cv_rank1_by_pca_dims": {k: round(v, 4) for k, v in self.fused_by_dims.items()},
                "folds_skipped": list(self.folds_skipped), "cv_probes": self.probes,
                "cv_probes_without_match": self.probes_without_match}


def identity_folds(labels: npt.ArrayLike, folds: int, rng: np.random.Generator) -> list[npt.NDArray[np.bool_]]:
    """``folds`` masks over the crops, each holding a random share of the identities (every identity in one)."""
    y = np.asarray(labels)
    names = np.unique(y)
    folds = check_int("folds", folds, 2)
    if names.size < 2 * folds:
        raise ValueError(f"{folds} folds need >= {2 * folds} identities (2 per fold), got {names.size}")
    fold_of = dict(zip(names[rng.permutation(names.size)].tolist(), np.arange(names.size) % folds, strict=True))
    which = np.array([fold_of[v] for v in y.tolist()])
    return [which == k for k in range(folds)]


def _scores(metric: LinearMetric, x: npt.NDArray[np.float64], labels: npt.NDArray[Any],
            valid: npt.NDArray[np.bool_]) -> tuple[float, float]:
    s = rank_scores(metric.distances(x, x), labels, labels, valid)
    return s.rank(1), s.mean_average_precision


def select_parameters(scores: Mapping[str, npt.ArrayLike], labels: npt.ArrayLike, cameras: Sequence[str],
                      grid: SearchGrid, folds: int, rng: np.random.Generator,
                      progress: Callable[[int, int], None] | None = None) -> Selection:
    """Choose the metric parameters on ``scores`` (per block of ``FEATURES``: (n, k) PCA scores, leading
    component first, k >= the grid's most), ``labels`` and ``cameras`` (one per row) by ``folds``-fold
    cross-validation over the identities (see the module doc); ``progress(done, total)`` after each fold.
    :class:`NoCrossCameraMatch` if no fold has a person seen by two cameras."""
    y = np.asarray(labels)
    cams = list(cameras)
    need = grid.max_dims()
    blocks = {}
    for b in FEATURES:
        x = np.asarray(scores[b], dtype=np.float64)
        if x.ndim != 2 or x.shape[0] != y.size or x.shape[1] < need[b]:
            raise ValueError(f"scores[{b!r}] must be ({y.size}, >= {need[b]}), got {x.shape}")
        blocks[b] = x[:, :need[b]]
    if len(cams) != y.size:
        raise ValueError(f"cameras must give one camera per row ({y.size}), got {len(cams)}")
    full = np.hstack([blocks[b] for b in FEATURES])
    offsets = dict(zip(FEATURES, np.cumsum([0, *(need[b] for b in FEATURES)])[:-1].tolist(), strict=True))

    def columns(feature: str, dims: tuple[int, ...]) -> npt.NDArray[np.intp]:
        names = FEATURES if feature == FUSED else (feature,)
        return np.concatenate([offsets[b] + np.arange(d) for b, d in zip(names, dims, strict=True)])

    candidates: dict[str, list[tuple[int, ...]]] = {f: [] for f in METRIC_FEATURES}
    for pair in grid.pca_dims:
        for f in METRIC_FEATURES:
            key = pair if f == FUSED else (pair[FEATURES.index(f)],)
            if key not in candidates[f]:
                candidates[f].append(key)
    results: dict[tuple[str, str, tuple[int, ...], float, int | None], list[tuple[float, float]]] = {}
    masks = identity_folds(y, folds, rng)
    skipped: list[str] = []
    probes = without_match = 0
    for k, held in enumerate(masks):
        train, test = ~held, held
        valid = ~camera_mask([cams[i] for i in np.flatnonzero(test)], [cams[i] for i in np.flatnonzero(test)])
        np.fill_diagonal(valid, False)
        matched = ((y[test][:, None] == y[test][None, :]) & valid).any(axis=1)
        probes, without_match = probes + int(matched.sum()), without_match + int((~matched).sum())
        if not matched.any():
            skipped.append(f"fold {k + 1} of {folds}: none of its {np.unique(y[test]).size} people is seen by two "
                           f"cameras")
            if progress:
                progress(k + 1, folds)
            continue
        cov = pair_covariances(full[train], y[train])
        for f in METRIC_FEATURES:
            for dims in candidates[f]:
                cols = columns(f, dims)
                sub = cov.subset(cols)
                xt = full[np.ix_(test, cols)]
                caps = [c for c in grid.subspace_dims if c is None or c < cols.size]
                for reg in grid.regularisations:
                    try:
                        metrics = xqda_for_dims(sub, regularisation=reg, max_dims=caps)
                        for cap, metric in zip(caps, metrics, strict=True):
                            results.setdefault(("xqda", f, dims, reg, cap), []).append(
                                _scores(metric, xt, y[test], valid))
                        results.setdefault(("kissme", f, dims, reg, None), []).append(
                            _scores(kissme_from_covariances(sub, regularisation=reg), xt, y[test], valid))
                    except ValueError as exc:
                        raise ValueError(f"fold {k + 1} of {folds}: {exc}") from None
        if progress:
            progress(k + 1, folds)
    if len(skipped) == len(masks):
        raise NoCrossCameraMatch(f"no cross-validation fold has a person seen by two cameras ({'; '.join(skipped)})")

    def mean(key: tuple[str, str, tuple[int, ...], float, int | None]) -> tuple[float, float]:
        runs = np.array(results[key])
        return float(runs[:, 0].mean()), float(runs[:, 1].mean())

    def best(keys: list[tuple[str, str, tuple[int, ...], float, int | None]]
             ) -> tuple[tuple[str, str, tuple[int, ...], float, int | None], tuple[float, float]]:
        ranked = max(keys, key=mean)  # max keeps the first of equals: the grid's order (fewest components)
        return ranked, mean(ranked)

    fused_keys = [key for key in results if key[0] == "xqda" and key[1] == FUSED]
    by_dims: dict[str, float] = {}
    for dims in candidates[FUSED]:
        _, (r1, _) = best([key for key in fused_keys if key[2] == dims])
        by_dims["_".join(f"{b}{d}" for b, d in zip(FEATURES, dims, strict=True))] = r1
    chosen_dims = best(fused_keys)[0][2]
    pca_dims = dict(zip(FEATURES, chosen_dims, strict=True))
    chosen: dict[str, dict[str, Choice]] = {"xqda": {}, "kissme": {}}
    for method, f in product(("xqda", "kissme"), METRIC_FEATURES):
        dims = chosen_dims if f == FUSED else (pca_dims[f],)
        key, (r1, ap) = best([key for key in results if key[:3] == (method, f, dims)])
        chosen[method][f] = Choice(key[3], key[4], r1, ap)
    return Selection(pca_dims, chosen["xqda"], chosen["kissme"], folds, by_dims, tuple(skipped), probes,
                     without_match)
