"""Static clutter: tracks of things that never moved from where they appeared and never showed a face.

Cameras describe every person-sized cluster (a coat stand, a pillar); such a track is held back from the
published tracks once it has stood ``after_s`` within ``radius_m`` of its first detection without a face.
A walk away and back counts as moving: every detection is checked.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["StaticClutter"]


class StaticClutter:
    """Where each track appeared, until it moves (see the module doc); ``after_s`` 0 = never clutter."""

    def __init__(self, after_s: float, radius_m: float) -> None:
        self.after_s = after_s
        self.radius_m = radius_m
        self._birth: dict[int, tuple[float, float, float]] = {}  # track id -> (x, y, created s) until it moves
        self._moved: set[int] = set()  # tracks that moved away from where they appeared

    def follow(self, associations: Iterable[tuple[int, int]], positions: NDArray[np.float64], stamp: float) -> None:
        """The frame's (track, detection) pairs at ``positions`` (N, 2)."""
        if not self.after_s:
            return
        for tid, det in associations:
            if tid in self._moved:
                continue
            x, y = float(positions[det, 0]), float(positions[det, 1])
            birth = self._birth.get(tid)
            if birth is None:
                self._birth[tid] = (x, y, stamp)
            elif math.hypot(x - birth[0], y - birth[1]) > self.radius_m:
                self._moved.add(tid)
                del self._birth[tid]

    def forget(self, track_id: int) -> None:
        """The track was deleted."""
        self._birth.pop(track_id, None)
        self._moved.discard(track_id)

    def among(self, snaps: list[Any], records: Mapping[int, Any]) -> set[int]:
        """The ids of the track snapshots that are static clutter now (``records``: track id -> its record; tracks
        whose record counts face observations never are)."""
        if not self.after_s:
            return set()
        return {snap.track_id for snap in snaps if snap.track_id in self._birth
                and getattr(records.get(snap.track_id), "face_observations", 0) == 0
                and snap.stamp_s - self._birth[snap.track_id][2] >= self.after_s}
