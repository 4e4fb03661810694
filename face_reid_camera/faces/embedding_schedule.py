"""Which detected faces to embed in this frame when embedding every face would take too long.

A per-frame budget (milliseconds) bounds the embedder's time. Heads are followed from frame to frame by
nearest position (camera frame, metres), so every visible person's face is refreshed in turn: faces never
embedded come first (best quality first), then the ones embedded longest ago. The cost per face is a
running mean of measured times (until the first measurement every face is embedded); at least one face is
embedded per frame so the schedule always moves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import check_real

__all__ = ["EmbeddingScheduler"]


@dataclass
class _Head:
    position: NDArray[np.float64]
    last_embedded_s: float
    last_seen_s: float


class EmbeddingScheduler:
    """Chooses the faces to embed under ``budget_ms`` per frame (0 = all of them, no scheduling).

    ``match_radius_m``: a head within this distance of one seen in an earlier frame is the same head (m).
    ``forget_after_s``: heads not seen for this long are forgotten (s).
    """

    def __init__(self, budget_ms: float, match_radius_m: float = 0.4, forget_after_s: float = 2.0) -> None:
        self.budget_ms = check_real("budget_ms", budget_ms, 0.0, 1e6)
        self.match_radius_m = check_real("match_radius_m", match_radius_m, 0.0, 100.0, low_open=True)
        self.forget_after_s = check_real("forget_after_s", forget_after_s, 0.0, 1e6, low_open=True)
        self.cost_ms_per_face: float | None = None  # running mean of the measured cost
        self._heads: list[_Head] = []
        self._matched: list[int | None] = []

    def choose(self, stamp_s: float, heads_cam: NDArray[np.float64], quality: NDArray[np.float64]) -> list[int]:
        """Indices of the faces (rows of ``heads_cam`` (n, 3), their ``quality``) to embed now, in order."""
        n = len(quality)
        self._heads = [h for h in self._heads if stamp_s - h.last_seen_s <= self.forget_after_s]
        self._matched = self._match(np.asarray(heads_cam, dtype=np.float64).reshape(n, 3), stamp_s)
        if self.budget_ms == 0.0 or n == 0:
            return list(range(n))
        staleness = np.array([stamp_s - self._heads[m].last_embedded_s for m in self._matched if m is not None])
        order = sorted(range(n), key=lambda i: (-staleness[i], -float(quality[i]), i))
        cost = self.cost_ms_per_face
        fit = n if cost is None or cost <= 0.0 else max(1, int(self.budget_ms // cost))
        return order[:fit]

    def embedded(self, stamp_s: float, chosen: list[int], elapsed_ms: float) -> None:
        """Record that the faces ``chosen`` (indices given to the last :meth:`choose`) took ``elapsed_ms``."""
        for i in chosen:
            m = self._matched[i]
            if m is not None:
                self._heads[m].last_embedded_s = stamp_s
        if chosen and elapsed_ms >= 0.0:
            per_face = elapsed_ms / len(chosen)
            prev = self.cost_ms_per_face
            self.cost_ms_per_face = per_face if prev is None else 0.8 * prev + 0.2 * per_face

    def _match(self, heads: NDArray[np.float64], stamp_s: float) -> list[int | None]:
        """Greedy nearest matching of this frame's heads to remembered ones; unmatched heads are added."""
        out: list[int | None] = [None] * len(heads)
        if self._heads and len(heads):
            known = np.stack([h.position for h in self._heads])
            d = np.linalg.norm(heads[:, None, :] - known[None, :, :], axis=2)
            for flat in np.argsort(d, axis=None):
                i, j = divmod(int(flat), d.shape[1])
                if d[i, j] > self.match_radius_m:
                    break
                if out[i] is None and j not in out:
                    out[i] = j
        for i, m in enumerate(out):
            if m is None:
                self._heads.append(_Head(heads[i].copy(), -math.inf, stamp_s))
                out[i] = len(self._heads) - 1
            else:
                self._heads[m].position = heads[i].copy()
                self._heads[m].last_seen_s = stamp_s
        return out
