"""Re-identification ranking scores: CMC (rank-k accuracy) and mean average precision.

Each probe's gallery entries are sorted by distance; rank-k = share of probes whose first correct gallery
entry is among the k nearest; AP = the mean precision at each correct entry's rank, mAP over probes.
Probes whose person is not in the gallery are left out (counted).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["RankScores", "rank_scores"]


@dataclass(frozen=True)
class RankScores:
    """``cmc[k - 1]`` = rank-k accuracy (k = 1..gallery size); mAP; probes scored / left out."""

    cmc: npt.NDArray[np.float64]
    mean_average_precision: float
    probes: int
    probes_without_match: int

    def rank(self, k: int) -> float:
        """Rank-k accuracy (the last value beyond the gallery size)."""
        if k < 1:
            raise ValueError(f"k must be >= 1, got {k}")
        return float(self.cmc[min(k, self.cmc.size) - 1])


def rank_scores(distances: npt.ArrayLike, probe_labels: npt.ArrayLike, gallery_labels: npt.ArrayLike,
                valid: npt.ArrayLike | None = None) -> RankScores:
    """Scores of a (probes, gallery) distance matrix with the person label of every probe and gallery row
    (ties keep the gallery order); ``valid`` (probes, gallery) False = that gallery entry does not count for
    that probe (e.g. seen by the probe's own camera)."""
    d = np.asarray(distances, dtype=np.float64)
    p, g = np.asarray(probe_labels), np.asarray(gallery_labels)
    if d.ndim != 2 or d.shape != (p.size, g.size):
        raise ValueError(f"distances must be (probes {p.size}, gallery {g.size}), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError("distances contain NaN or Inf")
    ok = np.ones(d.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if ok.shape != d.shape:
        raise ValueError(f"valid must have the distances' shape {d.shape}, got {ok.shape}")
    order = np.argsort(np.where(ok, d, np.inf), axis=1, kind="stable")  # excluded entries rank last
    correct = (g[order] == p[:, None]) & np.take_along_axis(ok, order, axis=1)  # (probes, gallery) by rank
    has = correct.any(axis=1)
    correct = correct[has]
    if not correct.shape[0]:
        raise ValueError("no probe's person is in the gallery")
    first = np.argmax(correct, axis=1)
    cmc = np.cumsum(np.bincount(first, minlength=g.size)) / correct.shape[0]
    hits = np.cumsum(correct, axis=1)
    ranks = np.arange(1, g.size + 1)
    ap = (np.where(correct, hits / ranks, 0.0).sum(axis=1) / correct.sum(axis=1))
    return RankScores(cmc.astype(np.float64), float(ap.mean()), int(correct.shape[0]), int(np.count_nonzero(~has)))
