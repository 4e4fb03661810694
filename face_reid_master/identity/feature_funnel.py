"""Feature funnel (second seed, Algorithm 2): evidence levels applied from the most reliable, each pruning
the candidates the next one may judge.

Level k keeps the candidates whose distance is below ``alpha_k`` times the smallest distance at that level
among those still in; the candidates pruned are abandoned. (The seed's score-level baseline, every level's
ratios summed for every candidate, made more wrong body decisions per right one on the development
scenarios and is not offered.)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ["funnel_survivors", "gaussian_log_ratio"]

FloatArray = npt.NDArray[np.float64]


def funnel_survivors(distances: Sequence[npt.ArrayLike], alphas: Sequence[float]) -> npt.NDArray[np.bool_]:
    """Which candidates reach the last level: ``distances[k]`` (n, candidates) are level k's distances (NaN:
    not measured, never prunes), ``alphas[k]`` (> 1) its pruning factor (one fewer than levels: the last
    level only scores). (n, candidates) mask."""
    if len(alphas) != max(len(distances) - 1, 0):
        raise ValueError(f"alphas must hold one factor per level but the last ({len(distances) - 1}), got "
                         f"{len(alphas)}")
    levels = [np.atleast_2d(np.asarray(d, dtype=np.float64)) for d in distances]
    keep = np.ones(levels[0].shape, dtype=bool)
    for d, alpha in zip(levels[:-1], alphas, strict=True):
        if not alpha > 1.0:
            raise ValueError(f"every alpha must be > 1 (1 keeps only the nearest), got {alpha}")
        measured = np.isfinite(d)
        nearest = np.where(keep & measured, d, np.inf).min(axis=1, keepdims=True)
        keep &= ~measured | (d <= alpha * nearest)
    return keep


def gaussian_log_ratio(difference: npt.ArrayLike, same_std: float, other_std: float) -> FloatArray:
    """log N(d; 0, same_std) / N(d; 0, other_std) of a measured difference (e.g. two heights, m)."""
    d = np.asarray(difference, dtype=np.float64)
    return np.log(other_std / same_std) - 0.5 * d * d * (1.0 / same_std**2 - 1.0 / other_std**2)
