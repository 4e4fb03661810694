"""One camera's floor counts over a rectangle of world cells: what the camera's floor map sends and the master's
camera map fuses (the fields of face_reid_msgs/FloorOccupancy)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["COUNT_MAX", "FloorOccupancySnapshot"]

COUNT_MAX = 65535  # counts travel as uint16


@dataclass(frozen=True)
class FloorOccupancySnapshot:
    """One camera's counts over a rectangle of cells (the fields of face_reid_msgs/FloorOccupancy).

    ``floor_counts`` / ``occupied_counts``: (height, width) uint16, row = y, col = x; cell (row, col) covers
    x in [origin_x_m + col r, + r), y in [origin_y_m + row r, + r) of the world frame (r = ``resolution_m``).
    """

    camera_id: str
    stamp_s: float
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    min_height_m: float
    max_height_m: float
    frames: int
    floor_counts: NDArray[np.uint16]
    occupied_counts: NDArray[np.uint16]

    def __post_init__(self) -> None:
        if not isinstance(self.camera_id, str):
            raise ValueError(f"camera_id must be a string, got {self.camera_id!r}")
        for name in ("stamp_s", "origin_x_m", "origin_y_m", "min_height_m", "max_height_m"):
            if not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise ValueError(f"resolution_m must be a positive cell side in metres, got {self.resolution_m!r}")
        if self.frames < 0:
            raise ValueError(f"frames must be >= 0, got {self.frames!r}")
        floor = np.asarray(self.floor_counts)
        occ = np.asarray(self.occupied_counts)
        if floor.ndim != 2 or floor.shape != occ.shape:
            raise ValueError(f"floor_counts {floor.shape} and occupied_counts {occ.shape} must be equal 2-D shapes")
        for name, arr in (("floor_counts", floor), ("occupied_counts", occ)):
            if arr.size and (arr.min() < 0 or arr.max() > COUNT_MAX):
                raise ValueError(f"{name} must be counts in [0, {COUNT_MAX}]")
        object.__setattr__(self, "floor_counts", floor.astype(np.uint16, copy=False))
        object.__setattr__(self, "occupied_counts", occ.astype(np.uint16, copy=False))

    @property
    def width(self) -> int:
        return int(self.floor_counts.shape[1])

    @property
    def height(self) -> int:
        return int(self.floor_counts.shape[0])
