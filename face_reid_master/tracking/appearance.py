"""What each track looks like: its last few body-appearance embeddings, for appearance-aware association.

A body descriptor embedded by the learned metric (:meth:`~face_reid_master.body.metric_file.BodyFeatureMetric.embed`)
compares with plain Euclidean distances in the metric's units (1 = the median distance between two different
people). A track keeps its newest ``size`` embeddings; its distance to a detection is the smallest over them
(a person seen from the front and from the back looks different: the gallery holds both).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["AppearanceGallery", "appearance_distances"]

F32 = NDArray[np.float32]


class AppearanceGallery:
    """The newest ``size`` embeddings of one track (a ring; empty until its first described detection)."""

    __slots__ = ("_next", "_rows", "_size", "count")

    def __init__(self, size: int) -> None:
        self._size = size
        self._rows = np.empty((0, 0), dtype=np.float32)  # allocated by the first embedding (its length)
        self._next = 0
        self.count = 0

    def add(self, embedding: F32) -> None:
        """Keep ``embedding`` (the oldest one goes once the gallery is full)."""
        if self._rows.shape[1] != embedding.shape[0]:  # the first one, or another metric: start afresh
            self._rows = np.empty((self._size, embedding.shape[0]), dtype=np.float32)
            self._next = self.count = 0
        self._rows[self._next] = embedding
        self._next = (self._next + 1) % self._rows.shape[0]
        self.count = min(self.count + 1, self._rows.shape[0])

    @property
    def rows(self) -> F32:
        """The kept embeddings (count, dim), in no particular order."""
        return self._rows[: self.count]


def appearance_distances(galleries: list[AppearanceGallery], embeddings: F32) -> NDArray[np.float64]:
    """(tracks, detections) smallest distance between each track's gallery and each detection's embedding;
    NaN where the track has no embedding yet or the detection none (a NaN row of ``embeddings``)."""
    n, m = len(galleries), embeddings.shape[0]
    out = np.full((n, m), np.nan)
    described = np.flatnonzero(np.isfinite(embeddings).all(axis=1))
    counts = np.array([g.count for g in galleries], dtype=np.intp)
    tracks = np.flatnonzero(counts)
    if described.size == 0 or tracks.size == 0:
        return out
    rows = np.concatenate([galleries[i].rows for i in tracks.tolist()]).astype(np.float64)
    det = embeddings[described].astype(np.float64)
    d2 = (rows * rows).sum(axis=1)[:, None] + (det * det).sum(axis=1)[None, :] - 2.0 * rows @ det.T
    starts = np.concatenate([[0], np.cumsum(counts[tracks])[:-1]])
    nearest = np.minimum.reduceat(d2, starts, axis=0)
    out[np.ix_(tracks, described)] = np.sqrt(np.maximum(nearest, 0.0))
    return out
