"""One camera's floor-level occupancy summary: per 2-D world cell, how many depth points hit the floor and how many
fell in an obstacle band above it (default 0.1-0.3 m: what a robot would bump into). No images leave the camera.

The master fuses the summaries of all cameras into an occupancy grid (``face_reid_master.robot.camera_map``). Cells
are on one world lattice (cell (i, j) covers x in [i r, (i+1) r), y likewise) so cameras' grids line up, and only a
square of side 2 ``max_range_m`` around the camera is kept (a bounded message). Pure numpy: np.bincount, no
per-point Python.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose, depth_to_points
from face_reid_camera.common.floor_snapshot import COUNT_MAX, FloorOccupancySnapshot
from face_reid_camera.common.param_table import param, validate_fields

__all__ = ["FloorOccupancyAccumulator", "FloorOccupancyConfig"]

@dataclass(frozen=True)
class FloorOccupancyConfig:
    """The camera node's ``floor_map_*`` parameters (off by default: ``period_s`` = 0 computes nothing)."""

    period_s: float = param(
        0.0, "Publish this camera's floor occupancy summary (face_reid_msgs/FloorOccupancy, for face-reid-map) every "
        "this many seconds (s; 0 = off, nothing is computed).", low=0.0, high=86400.0)
    resolution_m: float = param(0.05, "Cell side of the floor occupancy grid (m).", low=0.01, high=1.0)
    min_height_m: float = param(
        0.1, "Bottom of the obstacle band: points this high above the floor or higher count as obstacles (m).",
        low=0.0, high=3.0, low_open=True)
    max_height_m: float = param(
        0.3, "Top of the obstacle band: points higher than this above the floor are not counted (m).",
        low=0.0, high=3.0, low_open=True)
    floor_tolerance_m: float = param(
        0.04, "Points within this height of the floor (z = 0) count as floor: the cell is seen free (m).",
        low=0.0, high=0.5, low_open=True)
    max_range_m: float = param(
        6.0, "Only points within this horizontal distance of the camera are counted; bounds the grid (m).",
        low=0.1, high=50.0)
    max_cells: int = param(
        65536, "Most cells a summary may cover; (2 max_range_m / resolution_m + 2)^2 must fit (count).",
        low=1, high=10_000_000)
    depth_stride_px: int = param(
        4, "Floor occupancy uses every n-th depth row and column (px).", low=1, high=64)
    every_frames: int = param(
        10, "Floor occupancy counts one processed depth frame in this many (count; keeps the added cost small).",
        low=1, high=100_000)

    def __post_init__(self) -> None:
        validate_fields(self)
        if self.min_height_m >= self.max_height_m:
            raise ValueError(f"min_height_m ({self.min_height_m}) must be < max_height_m ({self.max_height_m})")
        if self.floor_tolerance_m >= self.min_height_m:
            raise ValueError(f"floor_tolerance_m ({self.floor_tolerance_m}) must be < min_height_m "
                             f"({self.min_height_m}): floor and obstacle band would overlap")
        side = self.side_cells
        if side * side > self.max_cells:
            raise ValueError(f"max_range_m ({self.max_range_m}) at resolution_m ({self.resolution_m}) needs "
                             f"{side * side} cells > max_cells ({self.max_cells})")

    @property
    def enabled(self) -> bool:
        return self.period_s > 0

    @property
    def side_cells(self) -> int:
        """Cells along one side of the square kept around the camera (at most; the lattice may shift it)."""
        return math.floor(2 * self.max_range_m / self.resolution_m) + 2


class FloorOccupancyAccumulator:
    """Counts one camera's world-frame points into floor and obstacle-band cells (cumulative since the start).

    When a count would pass 65535 every count is halved (ratios kept; old evidence fades slowly).
    """

    def __init__(self, config: FloorOccupancyConfig, camera_id: str, camera_xy_m: tuple[float, float]) -> None:
        if not isinstance(config, FloorOccupancyConfig):
            raise ValueError(f"config must be a FloorOccupancyConfig, got {type(config).__name__}")
        cx, cy = (float(v) for v in camera_xy_m)
        if not (math.isfinite(cx) and math.isfinite(cy)):
            raise ValueError(f"camera_xy_m must be finite, got {camera_xy_m!r}")
        self.config = config
        self.camera_id = str(camera_id)
        self._centre = (cx, cy)
        r, reach = config.resolution_m, config.max_range_m
        self._col0 = math.floor((cx - reach) / r)
        self._row0 = math.floor((cy - reach) / r)
        self._cols = math.floor((cx + reach) / r) - self._col0 + 1
        self._rows = math.floor((cy + reach) / r) - self._row0 + 1
        self._floor = np.zeros(self._rows * self._cols, dtype=np.int64)
        self._band = np.zeros(self._rows * self._cols, dtype=np.int64)
        self.frames = 0
        self.stamp_s = 0.0
        self._offered = 0

    def due(self) -> bool:
        """Count a frame now? True for one frame in ``every_frames`` (the first one included)."""
        self._offered += 1
        return (self._offered - 1) % self.config.every_frames == 0

    def add_depth(self, depth_m: NDArray[np.floating], intrinsics: CameraIntrinsics, pose: CameraPose,
                  stamp_s: float) -> None:
        """Count a depth image (metres, 0/NaN invalid) seen from ``pose``, on a ``depth_stride_px`` stride."""
        points = depth_to_points(depth_m, intrinsics, self.config.depth_stride_px)
        self.add_points(pose.to_world(points), stamp_s)

    def add_points(self, points_world: NDArray[np.floating], stamp_s: float) -> None:
        """Count (N, 3) world-frame points (z up, floor at 0) as one frame."""
        cfg = self.config
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        z = pts[:, 2]
        floor = np.abs(z) <= cfg.floor_tolerance_m
        band = (z >= cfg.min_height_m) & (z <= cfg.max_height_m)
        keep = floor | band
        pts, floor = pts[keep], floor[keep]
        dx, dy = pts[:, 0] - self._centre[0], pts[:, 1] - self._centre[1]
        near = dx * dx + dy * dy <= cfg.max_range_m ** 2  # NaN compares False
        pts, floor = pts[near], floor[near]
        col = np.floor(pts[:, 0] / cfg.resolution_m).astype(np.int64) - self._col0
        row = np.floor(pts[:, 1] / cfg.resolution_m).astype(np.int64) - self._row0
        inside = (col >= 0) & (col < self._cols) & (row >= 0) & (row < self._rows)
        flat = (row * self._cols + col)[inside]
        floor = floor[inside]
        size = self._floor.size
        self._floor += np.bincount(flat[floor], minlength=size)
        self._band += np.bincount(flat[~floor], minlength=size)
        while max(int(self._floor.max()), int(self._band.max())) > COUNT_MAX:
            self._floor >>= 1
            self._band >>= 1
        self.frames += 1
        self.stamp_s = max(self.stamp_s, float(stamp_s))

    def snapshot(self) -> FloorOccupancySnapshot | None:
        """The counts cropped to the cells any point fell in, or None before any point was counted."""
        seen = ((self._floor > 0) | (self._band > 0)).reshape(self._rows, self._cols)
        if not seen.any():
            return None
        rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
        r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
        floor = self._floor.reshape(self._rows, self._cols)[r0:r1, c0:c1]
        band = self._band.reshape(self._rows, self._cols)[r0:r1, c0:c1]
        r = self.config.resolution_m
        return FloorOccupancySnapshot(
            camera_id=self.camera_id, stamp_s=self.stamp_s, resolution_m=r,
            origin_x_m=(self._col0 + c0) * r, origin_y_m=(self._row0 + r0) * r,
            min_height_m=self.config.min_height_m, max_height_m=self.config.max_height_m, frames=self.frames,
            floor_counts=floor.astype(np.uint16), occupied_counts=band.astype(np.uint16))
