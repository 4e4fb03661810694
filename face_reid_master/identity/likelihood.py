"""Skew-normal likelihoods of face-embedding distances (Koide et al. 2017, Sec. III-E).

The Bayesian face table needs p(d | same person) = N_p(d) and p(d | different person) = N_n(d), where
d is the L2 distance between two face embeddings.  Both are skew-normal densities fitted by maximum
likelihood to distances of positive / negative face pairs of the embedder actually used (the paper's
OpenFace values do not transfer to the dlib ResNet embedder).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import special as _special

from face_reid_camera.common.checks import check_real

__all__ = [
    "LikelihoodModel",
    "SkewNormal",
    "fit_likelihood_model",
    "fit_min_of_k_exponent",
    "fit_skewnormal",
    "load_likelihood_model",
    "save_likelihood_model",
]

FORMAT_TAG = "face_reid_likelihood/1"

_LOG_2 = math.log(2.0)
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_MAX_DISTANCE = 3.0  # L2 distances of 128-d face descriptors stay far below this
_SURVIVAL_GRID_POINTS = 4097  # log(1 - CDF) tables for the min-of-K likelihood, linear interpolation


def _as_finite_array(d: npt.ArrayLike, what: str) -> npt.NDArray[np.float64]:
    arr = np.asarray(d, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite (got NaN or Inf)")
    return arr


@dataclass(frozen=True)
class SkewNormal:
    """Skew-normal density, same parametrisation as scipy.stats.skewnorm(a=alpha, loc=xi, scale=omega)."""

    alpha: float
    xi: float
    omega: float

    def __post_init__(self) -> None:
        for name in ("alpha", "xi"):
            object.__setattr__(self, name, check_real(f"SkewNormal.{name}", getattr(self, name)))
        object.__setattr__(self, "omega", check_real("SkewNormal.omega (scale)", self.omega, 0.0, low_open=True))

    def pdf(self, d: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """2/omega * phi(z) * Phi(alpha z), z = (d - xi)/omega, vectorised (no scipy.stats overhead)."""
        z = (_as_finite_array(d, "distances") - self.xi) / self.omega
        return (2.0 / self.omega) * np.exp(-0.5 * z * z - _LOG_SQRT_2PI) * _special.ndtr(self.alpha * z)

    def logpdf(self, d: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """log pdf, accurate far in the tails (uses log Phi), so likelihood products never underflow."""
        return self._logpdf_unchecked(_as_finite_array(d, "distances"))

    def _logpdf_unchecked(self, d: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.float64]:
        z = (d - self.xi) / self.omega
        log_norm = _LOG_2 - math.log(self.omega) - _LOG_SQRT_2PI
        return log_norm - 0.5 * z * z + _special.log_ndtr(self.alpha * z)

    def to_dict(self) -> dict[str, float]:
        return {"alpha": self.alpha, "xi": self.xi, "omega": self.omega}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SkewNormal:
        try:
            return cls(alpha=data["alpha"], xi=data["xi"], omega=data["omega"])
        except KeyError as exc:
            raise ValueError(f"skew-normal parameters need alpha, xi, omega; missing {exc}") from None


def _log_survival_grid(sn: SkewNormal, lo: float, hi: float, n: int) -> npt.NDArray[np.float64]:
    """log(1 - CDF) of a skew-normal at n uniform points of [lo, hi].

    Integrates the (exact, log-space) density from the right with the trapezoid rule on the same step,
    continued 12 scales past hi, so deep tails keep full relative precision (the closed form with
    Owen's T cancels catastrophically in the light tail of alpha < 0).
    """
    step = (hi - lo) / (n - 1)
    n_ext = n + math.ceil(12.0 * sn.omega / step) + math.ceil(max(0.0, sn.xi - hi) / step) + 2
    x = lo + step * np.arange(n_ext)
    lf = sn._logpdf_unchecked(x)
    seg = np.logaddexp(lf[:-1], lf[1:]) + math.log(0.5 * step)  # log of each trapezoid
    log_s = np.logaddexp.accumulate(seg[::-1])[::-1]
    return log_s[:n]


@dataclass(frozen=True)
class LikelihoodModel:
    """N_p (same person) and N_n (different person) distance likelihoods plus the paper's constant c.

    ``new_person_scale_c`` is the paper's c (eq. 5): c > 1 biases towards "unknown / new person".

    ``k_exponent_positive`` / ``k_exponent_negative`` model eq. 4 taking the *minimum* over a face's K
    stored features: that minimum is distributed like the minimum of K_eff = K**exponent independent
    pair distances, density K_eff f(d) S(d)^(K_eff - 1) (S = 1 - CDF).  With 0 (the paper, and the shipped
    model) the pair likelihoods are used as they are.  Exponents fitted on independent photos overstate
    the evidence when the stored features are frames of a few glances (the usual case), so they are opt-in.
    """

    positive: SkewNormal
    negative: SkewNormal
    new_person_scale_c: float = 1.0
    k_exponent_positive: float = 0.0
    k_exponent_negative: float = 0.0
    metadata: Mapping[str, Any] = field(default_factory=dict, compare=False, hash=False)
    _monotone_range: tuple[float, float] = field(init=False, repr=False, compare=False, hash=False)
    _decision_distance: float = field(init=False, repr=False, compare=False, hash=False)
    _grid: tuple[float, float, Any, Any] = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        if not isinstance(self.positive, SkewNormal) or not isinstance(self.negative, SkewNormal):
            raise ValueError("LikelihoodModel.positive and .negative must be SkewNormal instances")
        c = check_real("new_person_scale_c", self.new_person_scale_c, 0.0, low_open=True)
        object.__setattr__(self, "new_person_scale_c", c)
        for name in ("k_exponent_positive", "k_exponent_negative"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), 0.0, 1.0))
        object.__setattr__(self, "metadata", dict(self.metadata))
        lo, cross, hi = self._find_decision_points()
        object.__setattr__(self, "_monotone_range", (lo, hi))
        object.__setattr__(self, "_decision_distance", cross)
        n = _SURVIVAL_GRID_POINTS
        object.__setattr__(
            self,
            "_grid",
            (
                lo,
                (n - 1) / (hi - lo),
                _log_survival_grid(self.positive, lo, hi, n),
                _log_survival_grid(self.negative, lo, hi, n),
            ),
        )

    def _find_decision_points(self) -> tuple[float, float, float]:
        """(d_lo, d_cross, d_hi): log N_p/N_n decreases on [d_lo, d_hi] (outside it the fitted tails are
        extrapolation) and crosses 0 at d_cross.

        Two skew-normals with different scales give a log-ratio that turns back up far in a tail (a very
        distant face would look like a match).  Distances are clipped to this range before evaluation.
        """
        grid = np.linspace(0.0, _MAX_DISTANCE, 6001)
        lr = self.positive._logpdf_unchecked(grid) - self.negative._logpdf_unchecked(grid)
        positive = np.flatnonzero(lr > 0.0)
        negative_after = np.flatnonzero(lr[positive[0] :] < 0.0) if positive.size else positive
        if negative_after.size == 0:
            raise ValueError(
                "likelihood model is not discriminative: log N_p/N_n must be > 0 at small distances and "
                f"< 0 at larger ones on [0, {_MAX_DISTANCE}] (are positive and negative swapped?)"
            )
        i_cross = int(positive[0] + negative_after[0])  # first + to - crossing: the decision distance
        i_lo = int(np.argmax(lr[:i_cross]))
        i_hi = i_cross + int(np.argmin(lr[i_cross:]))
        if np.any(np.diff(lr[i_lo : i_hi + 1]) > 1e-9):
            raise ValueError("log N_p/N_n is not monotone between its maximum and minimum: refit the model")
        from scipy import optimize

        def lr_at(d: float) -> float:
            return float(self.positive._logpdf_unchecked(np.array([d]))[0]
                         - self.negative._logpdf_unchecked(np.array([d]))[0])

        cross = optimize.brentq(lr_at, float(grid[i_cross - 1]), float(grid[i_cross]), xtol=1e-10)  # refine the grid
        return float(grid[i_lo]), float(cross), float(grid[i_hi])

    @property
    def monotone_distance_range(self) -> tuple[float, float]:
        """(d_lo, d_hi): distances are clipped to this range by :meth:`log_likelihood_ratio`."""
        return self._monotone_range

    @property
    def decision_distance(self) -> float:
        """The pair distance where N_p = N_n: below it one observation is evidence for "same person"."""
        return self._decision_distance

    def log_likelihood_ratio(
        self, d: npt.ArrayLike, n_features: npt.ArrayLike = 1
    ) -> npt.NDArray[np.float64]:
        """Evidence for "same face" of a distance d = min over ``n_features`` stored features (eq. 4).

        log p(d | same) - log p(d | different) with d clipped to the monotone range; with both
        k-exponents 0 (the paper) this is log N_p(d) - log N_n(d) whatever ``n_features``.  +inf (a face
        never compared, e.g. outside a search shortlist) maps to the weakest value.
        """
        arr = np.asarray(d, dtype=np.float64)
        if np.any(np.isnan(arr)) or np.any(arr == -np.inf):
            raise ValueError("distances must not be NaN or -inf")
        k = np.asarray(n_features, dtype=np.float64)
        if not np.all(np.isfinite(k)) or np.any(k < 1.0):
            raise ValueError("n_features must be >= 1")
        return self.log_ratio_trusted(arr, k)

    def log_ratio_trusted(
        self, d: npt.NDArray[np.floating[Any]], n_features: npt.NDArray[np.floating[Any]] | float = 1.0
    ) -> npt.NDArray[np.float64]:
        """:meth:`log_likelihood_ratio` without input checks, for callers that validated (float arrays,
        no NaN / -inf distances, ``n_features`` >= 1): the per-observation hot path of the Bayes table."""
        lo, hi = self._monotone_range
        arr = np.clip(d, lo, hi)
        lr = self.positive._logpdf_unchecked(arr) - self.negative._logpdf_unchecked(arr)
        if self.k_exponent_positive == 0.0 and self.k_exponent_negative == 0.0:
            return lr
        g_lo, inv_step, log_sp, log_sn = self._grid
        pos = (arr - g_lo) * inv_step
        i0 = np.minimum(pos.astype(np.intp), len(log_sp) - 2)
        frac = pos - i0
        sp = log_sp[i0] + frac * (log_sp[i0 + 1] - log_sp[i0])
        sn = log_sn[i0] + frac * (log_sn[i0 + 1] - log_sn[i0])
        k = np.asarray(n_features, dtype=np.float64)
        kp = k**self.k_exponent_positive
        kn = k**self.k_exponent_negative
        return lr + (np.log(kp) - np.log(kn)) + (kp - 1.0) * sp - (kn - 1.0) * sn

    def with_new_person_scale(self, c: float) -> LikelihoodModel:
        """Copy with another paper constant c."""
        return dataclasses.replace(self, new_person_scale_c=c)


def fit_skewnormal(distances: npt.ArrayLike) -> SkewNormal:
    """Maximum-likelihood skew-normal fit (scipy.stats.skewnorm.fit) of a 1-D sample of distances."""
    from scipy import stats

    d = _as_finite_array(distances, "distances")
    if d.ndim != 1:
        raise ValueError(f"distances must be 1-D, got shape {d.shape}")
    if d.size < 10:
        raise ValueError(f"need at least 10 distances to fit a skew-normal, got {d.size}")
    if float(np.ptp(d)) <= 0.0:
        raise ValueError("distances are all equal: cannot fit a skew-normal")
    alpha, xi, omega = stats.skewnorm.fit(d)
    return SkewNormal(alpha=float(alpha), xi=float(xi), omega=float(omega))


def fit_likelihood_model(
    positive_distances: npt.ArrayLike,
    negative_distances: npt.ArrayLike,
    new_person_scale_c: float = 1.0,
    metadata: Mapping[str, Any] | None = None,
) -> LikelihoodModel:
    """Fit N_p on same-identity pair distances and N_n on different-identity pair distances."""
    pos = _as_finite_array(positive_distances, "positive distances").ravel()
    neg = _as_finite_array(negative_distances, "negative distances").ravel()
    meta: dict[str, Any] = {
        "n_positive_pairs": int(pos.size),
        "n_negative_pairs": int(neg.size),
        "fitted_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "method": "scipy.stats.skewnorm.fit (MLE)",
    }
    meta.update(metadata or {})
    return LikelihoodModel(fit_skewnormal(pos), fit_skewnormal(neg), new_person_scale_c, metadata=meta)


def fit_min_of_k_exponent(min_distances_by_k: Mapping[int, npt.ArrayLike], pair_model: SkewNormal) -> float:
    """Exponent e of K_eff = s * K**e fitted (MLE over s and e) to samples of min-over-K distances.

    ``min_distances_by_k[K]`` holds distances min_k ||q - f_k|| of queries to K features of one person
    (the same person for the positive model, another person for the negative one).  The free scale s
    absorbs a mismatch of the pair model on this data, so e measures only how the minimum moves with K.
    """
    from scipy import optimize

    samples = []
    for k, dist in min_distances_by_k.items():
        if isinstance(k, bool) or int(k) < 1:
            raise ValueError(f"K must be an int >= 1, got {k!r}")
        samples.append((float(k), np.clip(_as_finite_array(dist, f"distances for K={k}").ravel(), 0, 3)))
    if len({k for k, _ in samples}) < 2:
        raise ValueError("need minimum distances for at least two different K")
    grid = np.linspace(0.0, _MAX_DISTANCE, _SURVIVAL_GRID_POINTS)
    log_s = _log_survival_grid(pair_model, 0.0, _MAX_DISTANCE, _SURVIVAL_GRID_POINTS)
    terms = [(k, pair_model._logpdf_unchecked(d), np.interp(d, grid, log_s)) for k, d in samples]

    def nll(params: npt.NDArray[np.float64]) -> float:
        log_scale, e = float(params[0]), float(params[1])
        total = 0.0
        for k, lf, ls in terms:
            ke = math.exp(log_scale) * k**e
            total -= float(np.sum(math.log(ke) + lf + (ke - 1.0) * ls))
        return total

    res = optimize.minimize(nll, x0=np.array([0.0, 0.5]), bounds=[(-5.0, 5.0), (0.0, 1.0)], method="L-BFGS-B")
    return float(res.x[1])


def save_likelihood_model(model: LikelihoodModel, path: str | Path) -> None:
    """Write the model as JSON (parameters + metadata such as pair counts, embedder, date)."""
    doc = {
        "format": FORMAT_TAG,
        "positive": model.positive.to_dict(),
        "negative": model.negative.to_dict(),
        "new_person_scale_c": model.new_person_scale_c,
        "k_exponent_positive": model.k_exponent_positive,
        "k_exponent_negative": model.k_exponent_negative,
        "metadata": dict(model.metadata),
    }
    Path(path).write_text(json.dumps(doc, indent=2, sort_keys=False) + "\n", encoding="utf-8")


def load_likelihood_model(path: str | Path) -> LikelihoodModel:
    """Read a JSON model written by :func:`save_likelihood_model`; ValueError on a malformed file."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_TAG:
        raise ValueError(f"{path}: not a face likelihood model (expected format {FORMAT_TAG!r})")
    try:
        return LikelihoodModel(
            positive=SkewNormal.from_dict(doc["positive"]),
            negative=SkewNormal.from_dict(doc["negative"]),
            new_person_scale_c=doc.get("new_person_scale_c", 1.0),
            k_exponent_positive=doc.get("k_exponent_positive", 0.0),
            k_exponent_negative=doc.get("k_exponent_negative", 0.0),
            metadata=doc.get("metadata", {}),
        )
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: malformed likelihood model ({exc})") from None
