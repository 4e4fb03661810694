"""The recent bodies of every learned face in one array, so that a body is compared with all of them at once.

Face slot s owns rows [s * size, (s + 1) * size) (a ring of its newest ``size`` bodies). With each row: its
stamp (rows older than a window no longer count; a free or unwritten row has -inf) and the person's head
height (NaN: unknown). One GEMM over the whole array and
a min over each slot's rows give every face's nearest body: no per-face loop.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import numpy.typing as npt

__all__ = ["FaceBodyPool"]

F32 = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]


class FaceBodyPool:
    """Every face's newest ``size`` body embeddings, stamps and head heights (see the module doc)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.dim = 0
        self.slot_of: dict[int, int] = {}
        self._free: list[int] = []
        self._alloc(0, 0)

    def _alloc(self, slots: int, dim: int) -> None:
        n = slots * self.size
        self.rows = np.zeros((n, dim), np.float32)
        self.norms = np.zeros(n)  # squared norms of the rows
        self.stamps = np.full(n, -math.inf)
        self.heights = np.full(n, math.nan)
        self.face = np.zeros(slots, np.int64)  # face id per slot (0: free)
        self.next = np.zeros(slots, np.int64)

    @property
    def slots(self) -> int:
        return int(self.face.size)

    def _grow(self) -> None:
        old = (self.rows, self.norms, self.stamps, self.heights, self.face, self.next)
        n_old = self.slots
        self._alloc(max(8, 2 * n_old), self.dim)
        for new, prev in zip((self.rows, self.norms, self.stamps, self.heights, self.face, self.next), old,
                             strict=True):
            new[: prev.shape[0]] = prev
        self._free.extend(range(self.slots - 1, n_old - 1, -1))

    def add(self, face_id: int, embeddings: F32, stamp_s: float, heights: FloatArray) -> None:
        """Keep a face's new bodies (the oldest of its ring go). Another embedding length than the kept ones
        (another metric) starts every face afresh."""
        if embeddings.shape[1] != self.dim:
            self.dim, self.slot_of, self._free = embeddings.shape[1], {}, []
            self._alloc(0, self.dim)
        slot = self.slot_of.get(face_id)
        if slot is None:
            if not self._free:
                self._grow()
            slot = self.slot_of[face_id] = self._free.pop()
            self.face[slot] = face_id
        base = slot * self.size
        for row, height in zip(embeddings, heights, strict=True):
            i = base + int(self.next[slot])
            self.rows[i] = row
            self.norms[i] = float(row.astype(np.float64) @ row)
            self.stamps[i], self.heights[i] = stamp_s, height
            self.next[slot] = (self.next[slot] + 1) % self.size

    def release(self, face_id: int) -> None:
        """Drop a face's bodies."""
        slot = self.slot_of.pop(face_id, None)
        if slot is None:
            return
        rows = slice(slot * self.size, (slot + 1) * self.size)
        self.rows[rows] = 0.0
        self.norms[rows], self.stamps[rows], self.heights[rows] = 0.0, -math.inf, math.nan
        self.face[slot], self.next[slot] = 0, 0
        self._free.append(slot)

    def face_rows(self, face_id: int, since: float) -> F32:
        """A face's rows stamped at or after ``since``."""
        slot = self.slot_of.get(face_id)
        if slot is None:
            return np.zeros((0, self.dim), np.float32)
        rows = slice(slot * self.size, (slot + 1) * self.size)
        return self.rows[rows][self.stamps[rows] >= since]

    def recent_faces(self, since: float) -> npt.NDArray[np.int64]:
        """Face ids with a row stamped at or after ``since``."""
        if not self.slots:
            return np.zeros(0, np.int64)
        newest = self.stamps.reshape(self.slots, self.size).max(axis=1)
        return self.face[(newest >= since) & (self.face > 0)]

    def nearest(self, embeddings: F32, mask: npt.NDArray[np.bool_]) -> tuple[FloatArray, npt.NDArray[np.intp]]:
        """Per embedding (k, dim) and slot, the smallest squared distance to the slot's rows in ``mask`` (inf:
        none) and that row's index: ((k, slots), (k, slots))."""
        e = np.atleast_2d(embeddings).astype(np.float32, copy=False)
        d2 = self.norms[None, :] - 2.0 * (e @ self.rows.T).astype(np.float64) \
            + (e.astype(np.float64) ** 2).sum(axis=1)[:, None]
        d2[:, ~mask] = np.inf
        per_slot = d2.reshape(e.shape[0], self.slots, self.size)
        arg = per_slot.argmin(axis=2)
        best = np.take_along_axis(per_slot, arg[:, :, None], axis=2)[:, :, 0]
        return np.maximum(best, 0.0), arg + (np.arange(self.slots) * self.size)[None, :]

    def slot_heights(self, mask: npt.NDArray[np.bool_]) -> FloatArray:
        """Per slot, the median head height of its rows in ``mask`` (NaN: none measured)."""
        h = np.where(mask, self.heights, np.nan).reshape(self.slots, self.size)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slots: NaN is the answer
            return np.nanmedian(h, axis=1) if self.slots else np.zeros(0)
