"""The tracker's live tracks as one table: a numpy column (or a list of objects) per field, a row per track.

Vectorised steps read and write whole columns (``table.x[rows]``); creating and deleting tracks appends or
keeps rows of every column at once, so a new field is one declaration below.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.tracking.appearance import AppearanceGallery
from face_reid_master.tracking.history import TrackHistory
from face_reid_master.tracking.records import TrackSnapshot, TrackState

__all__ = ["TrackTable"]

_STATES = {int(s): s for s in TrackState}  # stored state code -> TrackState


def _empty(dtype: type, *shape: int) -> Any:
    """A factory of an empty column of ``dtype`` whose rows have ``shape``."""
    return lambda: np.zeros((0, *shape), dtype=dtype)


@dataclass
class TrackTable:
    """One row per live track (see the module doc)."""

    ids: NDArray[np.int64] = field(default_factory=_empty(np.int64))
    state: NDArray[np.int8] = field(default_factory=_empty(np.int8))  # TrackState codes
    created: NDArray[np.float64] = field(default_factory=_empty(np.float64))  # stamp of the first detection (s)
    last_seen: NDArray[np.float64] = field(default_factory=_empty(np.float64))  # stamp of the newest detection (s)
    hits: NDArray[np.int64] = field(default_factory=_empty(np.int64))  # detections associated
    x: NDArray[np.float64] = field(default_factory=_empty(np.float64, 4))  # newest posterior state (x, y, vx, vy)
    P: NDArray[np.float64] = field(default_factory=_empty(np.float64, 4, 4))  # its covariance
    t: NDArray[np.float64] = field(default_factory=_empty(np.float64))  # stamp of the newest posterior (s)
    zmeas: NDArray[np.float64] = field(default_factory=_empty(np.float64, 2))  # position of the newest measurement
    hist: list[TrackHistory] = field(default_factory=list)  # filter steps kept for late measurements
    looks: list[AppearanceGallery] = field(default_factory=list)  # body-appearance embeddings

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def append(self, **rows: Any) -> None:
        """Append rows: every field, each with the same number of rows (arrays for columns, lists for objects)."""
        if set(rows) != {f.name for f in dataclasses.fields(self)}:
            raise ValueError(f"append needs every field, got {sorted(rows)}")
        for f in dataclasses.fields(self):
            old = getattr(self, f.name)
            setattr(self, f.name, old + list(rows[f.name]) if isinstance(old, list)
                    else np.concatenate([old, np.asarray(rows[f.name], dtype=old.dtype)]))

    def keep(self, rows: NDArray[np.bool_]) -> None:
        """Keep only the rows where ``rows`` is True."""
        flags = rows.tolist()
        for f in dataclasses.fields(self):
            old = getattr(self, f.name)
            setattr(self, f.name, [v for v, k in zip(old, flags, strict=True) if k] if isinstance(old, list)
                    else old[rows])

    def detected(self, rows: NDArray[np.intp], heights: NDArray[np.float64], stamp: float, camera_id: str) -> None:
        """The tracks of ``rows`` were detected at ``stamp`` by ``camera_id`` with head ``heights`` (NaN:
        unknown): their sightings, hit counts, cameras and newest heights follow."""
        self.last_seen[rows] = np.maximum(self.last_seen[rows], stamp)
        self.created[rows] = np.minimum(self.created[rows], stamp)
        self.hits[rows] += 1
        for i, h in zip(rows.tolist(), heights.tolist(), strict=True):
            hist = self.hist[i]
            if hist.cameras.get(camera_id, -math.inf) < stamp:
                hist.cameras[camera_id] = stamp
            if h == h and stamp >= hist.height_stamp_s:  # finite (not NaN)
                hist.height_m, hist.height_stamp_s = h, stamp

    def hidden(self, rows: NDArray[np.intp], camera_id: str, previous_s: float, stamp: float, max_gap_s: float
               ) -> NDArray[np.bool_] | None:
        """Of ``rows``: the tracks ``camera_id`` saw within ``max_gap_s`` before ``stamp`` but not in its previous
        frame, at ``previous_s`` (hidden from it since, or gone); None for a first (inf) or a late frame."""
        if previous_s >= stamp:
            return None
        seen = np.array([self.hist[i].cameras.get(camera_id, -math.inf) for i in rows.tolist()])
        return (seen < previous_s) & (stamp - seen <= max_gap_s)

    def remember_looks(self, appearance: NDArray[np.float32], rows: NDArray[np.intp], cols: NDArray[np.intp],
                       created_cols: list[int]) -> None:
        """Add each described detection's embedding (row ``col`` of ``appearance``) to the gallery of the track it
        joined (``rows`` / ``cols``) or started (``created_cols``: the tracks just appended, in order)."""
        described = np.isfinite(appearance).all(axis=1)
        pairs = [(i, col) for i, col in zip(rows.tolist(), cols.tolist(), strict=True) if described[col]]
        if created_cols:  # new tracks were appended: their rows are the last ones
            first = self.ids.shape[0] - len(created_cols)
            pairs += [(first + k, col) for k, col in enumerate(created_cols) if described[col]]
        for i, col in pairs:
            self.looks[i].add(appearance[col])

    def snapshots(self, x: NDArray[np.float64], P: NDArray[np.float64], stamps: NDArray[np.float64],
                  window_start: float, include_tentative: bool) -> list[TrackSnapshot]:
        """The rows as snapshots with states ``x`` / ``P`` at ``stamps`` (predicted by the caller); the cameras
        that saw each track since ``window_start``."""
        out: list[TrackSnapshot] = []
        for i, (tid, code, t, created, last_seen, hits) in enumerate(zip(
                self.ids.tolist(), self.state.tolist(), stamps.tolist(), self.created.tolist(),
                self.last_seen.tolist(), self.hits.tolist(), strict=True)):
            state = _STATES[code]
            if not include_tentative and state is TrackState.TENTATIVE:
                continue
            hist = self.hist[i]
            out.append(TrackSnapshot(
                track_id=tid, state=state, position_xy=x[i, :2], velocity_xy=x[i, 2:], covariance=P[i], stamp_s=t,
                created_s=created, last_seen_s=last_seen, hits=hits,
                cameras=frozenset(c for c, t_cam in hist.cameras.items() if t_cam >= window_start),
                height_m=hist.height_m))
        return out
