"""Heads on the floor-plane height map: where a camera's depth clusters hold people.

The voxels of a frame are projected on the floor plane into a height map (cells of ``voxel_size_m``) whose
8-connected clusters are the objects in view (gaps narrower than ``cluster_tolerance_m`` bridged). A head is a
prominent local maximum of the map with a cap (a few cells within a drop of its top), a ring of lower cells
(shoulders) on both sides of the camera's line of sight, and no higher head of its cluster within
``heads_minimum_distance_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from face_reid_camera.people.ground_plane import GroundPlane

__all__ = ["OVERHEAD_RANGE_M", "FloorGrid", "HeadFinder", "principal_width"]

FloatArray = NDArray[np.float64]

# A head needs at least this many lower cells (shoulders) in its ring, and this many cells (its top
# included) within HEAD_CAP_RADIUS_M less than head_min_drop_m below its top.
_MIN_RING_CELLS = 2
_MIN_CAP_CELLS = 3
HEAD_CAP_RADIUS_M = 0.1
# The head position is averaged over its cap cells less than this below the top (metres).
_HEAD_CAP_DROP_M = 0.1
# Heads closer than this (horizontally) to the camera are seen from above: no line-of-sight sides.
OVERHEAD_RANGE_M = 0.3
_EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)


@dataclass
class FloorGrid:
    """Voxels projected on the floor plane: coordinates, dense height map and its 2-D clusters."""

    u: FloatArray  # (N,) floor coordinates of the voxels (m): p = u axis_u + v axis_v + h' normal
    v: FloatArray
    axis_u: FloatArray  # (3,) unit floor axes in the camera frame
    axis_v: FloatArray
    flat: NDArray[np.intp]  # (N,) flat grid cell of each voxel
    shape: tuple[int, int]
    height_map: FloatArray  # (cells,) highest voxel height per cell, -inf if empty
    top_voxel: NDArray[np.intp]  # (cells,) index of that highest voxel, -1 if empty
    labels: NDArray[np.intp]  # (cells,) 2-D cluster label of occupied cells, 0 if empty
    n_clusters: int


class HeadFinder:
    """The height map of a frame's voxels and the heads on it (see the module doc); ``config`` is the person
    detector's (voxel_size_m, head_annulus_*, cluster_tolerance_m, min_person_height_m, head_min_drop_m,
    upper_body_depth_m, max_head_plateau_fraction, min_shoulder_offset_m, heads_minimum_distance_m)."""

    def __init__(self, config: Any) -> None:
        self.config = config
        # Height-map geometry (cells of voxel_size_m): peak footprint, head ring offsets, gap bridging.
        cell = config.voxel_size_m
        reach = math.ceil(config.head_annulus_outer_m / cell)
        di, dj = np.mgrid[-reach : reach + 1, -reach : reach + 1]
        dist = np.hypot(di, dj) * cell
        in_ring = (dist >= config.head_annulus_inner_m) & (dist <= config.head_annulus_outer_m)
        self.ring_di, self.ring_dj = di[in_ring], dj[in_ring]
        self.ring_radius_cells = reach
        in_cap = dist <= max(HEAD_CAP_RADIUS_M, 1.5 * cell)
        self.cap_di, self.cap_dj = di[in_cap], dj[in_cap]
        self.peak_footprint = np.hypot(*np.mgrid[-2:3, -2:3]) <= 1.75
        self.bridge_cells = max(0, round(config.cluster_tolerance_m / cell) - 1)

    def floor_grid(self, obj: FloatArray, obj_h: FloatArray, plane: GroundPlane) -> FloorGrid:
        """Height map of the voxels on a padded floor-plane grid and its 8-connected clusters."""
        cell = self.config.voxel_size_m
        normal = plane.normal
        axis_u = np.array([1.0, 0.0, 0.0]) - normal[0] * normal  # camera x projected on the floor
        if np.linalg.norm(axis_u) < 1e-6:
            axis_u = np.array([0.0, 0.0, 1.0]) - normal[2] * normal
        axis_u /= np.linalg.norm(axis_u)
        axis_v = np.cross(normal, axis_u)
        u, v = obj @ axis_u, obj @ axis_v  # the camera is at u = v = 0

        pad = self.ring_radius_cells + 1  # ring/cap lookups never leave the grid
        iu = np.floor(u * (1.0 / cell)).astype(np.intp)
        iv = np.floor(v * (1.0 / cell)).astype(np.intp)
        iu -= iu.min() - pad
        iv -= iv.min() - pad
        shape = (int(iu.max()) + pad + 1, int(iv.max()) + pad + 1)
        flat = iu * shape[1] + iv
        height_map = np.full(shape[0] * shape[1], -np.inf)
        np.maximum.at(height_map, flat, obj_h)
        top_voxel = np.full(height_map.size, -1)
        is_top = obj_h >= height_map[flat]
        top_voxel[flat[is_top]] = np.flatnonzero(is_top)

        occupied = (height_map > -np.inf).reshape(shape)
        bridged = occupied  # gaps narrower than cluster_tolerance_m are bridged before labelling
        if self.bridge_cells > 0:
            bridged = ndimage.binary_dilation(
                occupied, structure=_EIGHT_CONNECTED, iterations=self.bridge_cells
            )
        labels, n_clusters = ndimage.label(bridged, structure=_EIGHT_CONNECTED)
        return FloorGrid(
            u,
            v,
            axis_u,
            axis_v,
            flat,
            shape,
            height_map,
            top_voxel,
            np.where(occupied, labels, 0).ravel(),
            n_clusters,
        )

    def heads(self, grid: FloorGrid, obj_h: FloatArray) -> NDArray[np.intp]:
        """Flat indices of the head cells: prominent local maxima, non-maximum suppressed."""
        cfg = self.config
        hmap, labels, width = grid.height_map, grid.labels, grid.shape[1]
        local_max = ndimage.maximum_filter(
            hmap.reshape(grid.shape), footprint=self.peak_footprint, mode="constant", cval=-np.inf
        )
        cand = np.flatnonzero((hmap >= cfg.min_person_height_m) & (hmap >= local_max.ravel()))
        if cand.size == 0:
            return cand
        # A head has a cap: >= 3 cells of its cluster within 0.1 m less than head_min_drop_m lower
        # (single-cell spikes of far-range depth noise and thin edges have none).
        cap = cand[:, None] + (self.cap_di * width + self.cap_dj)[None, :]
        top_h = hmap[cand][:, None]
        in_cap = (labels[cap] == labels[cand][:, None]) & (hmap[cap] > top_h - cfg.head_min_drop_m)
        cand = cand[np.count_nonzero(in_cap, axis=1) >= _MIN_CAP_CELLS]
        if cand.size == 0:
            return cand
        # Prominence over the ring of same-cluster cells comparable to the top (not more than
        # upper_body_depth_m lower, nor more than head_min_drop_m higher, e.g. a wall behind).
        ring = cand[:, None] + (self.ring_di * width + self.ring_dj)[None, :]
        ring_h = hmap[ring]
        top_h = hmap[cand][:, None]
        comparable = (
            (labels[ring] == labels[cand][:, None])
            & (ring_h >= top_h - cfg.upper_body_depth_m)
            & (ring_h <= top_h + cfg.head_min_drop_m)
        )
        low = comparable & (ring_h <= top_h - cfg.head_min_drop_m)  # shoulders
        n_ring = np.count_nonzero(comparable, axis=1)
        n_low = np.count_nonzero(low, axis=1)
        keep = (n_low >= _MIN_RING_CELLS) & (n_ring - n_low <= cfg.max_head_plateau_fraction * n_ring)
        cand, low = cand[keep], low[keep]
        if cand.size == 0:
            return cand
        # Shoulders flank a head: it needs lower ring cells on both sides of the line of sight, at
        # least min_shoulder_offset_m off it (rejects a corner of a flat object, or a top edge sloping
        # into an occlusion shadow). Ring cells nearer to another candidate of the cluster are that
        # one's (people standing side by side). Heads almost below the camera skip the test.
        low &= ~self._foreign_ring_cells(cand, labels[cand], width)
        tops = grid.top_voxel[cand]
        sight = np.stack([grid.u[tops], grid.v[tops]], axis=1)
        sight_norm = np.linalg.norm(sight, axis=1, keepdims=True)
        sight /= np.maximum(sight_norm, 1e-6)
        lateral = (
            self.ring_dj[None, :] * sight[:, :1] - self.ring_di[None, :] * sight[:, 1:]
        ) * cfg.voxel_size_m
        left = np.any(low & (lateral <= -cfg.min_shoulder_offset_m), axis=1)
        right = np.any(low & (lateral >= cfg.min_shoulder_offset_m), axis=1)
        cand = cand[(left & right) | (sight_norm[:, 0] < OVERHEAD_RANGE_M)]
        return cand if cand.size < 2 else self._suppressed(cand, grid, obj_h)

    def _suppressed(self, cand: NDArray[np.intp], grid: FloorGrid, obj_h: FloatArray) -> NDArray[np.intp]:
        """Non-maximum suppression: the candidates with no higher head (ties: lower index) of the same cluster
        within heads_minimum_distance_m."""
        tops = grid.top_voxel[cand]
        cu, cv, ch, cl = grid.u[tops], grid.v[tops], obj_h[tops], grid.labels[cand]
        close = (
            (cu[:, None] - cu[None, :]) ** 2 + (cv[:, None] - cv[None, :]) ** 2
        ) < self.config.heads_minimum_distance_m**2
        index = np.arange(cand.size)
        higher = (ch[None, :] > ch[:, None]) | (
            (ch[None, :] == ch[:, None]) & (index[None, :] < index[:, None])
        )
        return cand[~np.any(close & (cl[:, None] == cl[None, :]) & higher, axis=1)]

    def head_positions(self, grid: FloorGrid, heads: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
        """Floor coordinates (u, v) of each head: the mean of its cap's top voxels (one voxel is noisy far
        away)."""
        cap = heads[:, None] + (self.cap_di * grid.shape[1] + self.cap_dj)[None, :]
        cap_top = grid.top_voxel[cap]
        in_cap = (grid.labels[cap] == grid.labels[heads][:, None]) & (
            grid.height_map[cap] > grid.height_map[heads][:, None] - _HEAD_CAP_DROP_M
        )
        n_cap = np.count_nonzero(in_cap, axis=1)
        return (np.sum(np.where(in_cap, grid.u[cap_top], 0.0), axis=1) / n_cap,
                np.sum(np.where(in_cap, grid.v[cap_top], 0.0), axis=1) / n_cap)

    def _foreign_ring_cells(
        self, cand: NDArray[np.intp], cand_labels: NDArray[np.intp], width: int
    ) -> NDArray[np.bool_]:
        """(candidates, ring) mask of ring cells nearer to another candidate of the same cluster."""
        foreign = np.zeros((cand.size, self.ring_di.size), dtype=bool)
        if cand.size < 2:
            return foreign
        rows, cols = cand // width, cand % width
        d_row = rows[None, :] - rows[:, None]
        d_col = cols[None, :] - cols[:, None]
        # Competitors: other candidates of the cluster at least heads_minimum_distance_m away (nearer
        # ones are the same head) and close enough to reach into the ring.
        dist2 = d_row**2 + d_col**2
        apart = (self.config.heads_minimum_distance_m / self.config.voxel_size_m) ** 2
        near = (dist2 >= apart) & (dist2 <= (2 * self.ring_radius_cells) ** 2)
        near &= cand_labels[None, :] == cand_labels[:, None]
        first, second = np.nonzero(near)
        if first.size == 0:
            return foreign
        dr, dc = d_row[first, second][:, None], d_col[first, second][:, None]
        # Ring cell r is nearer to the other candidate (offset d) iff 2 r.d > |d|^2.
        nearer = 2 * (self.ring_di[None, :] * dr + self.ring_dj[None, :] * dc) > dr**2 + dc**2
        np.logical_or.at(foreign, first, nearer)
        return foreign


def principal_width(u: FloatArray, v: FloatArray) -> float:
    """Extent of floor-plane points along their principal axis (metres)."""
    if u.size < 2:
        return 0.0
    du, dv = u - u.mean(), v - v.mean()
    angle = 0.5 * math.atan2(2.0 * float(du @ dv), float(du @ du) - float(dv @ dv))  # major axis
    proj = du * math.cos(angle) + dv * math.sin(angle)
    return float(proj.max() - proj.min())
