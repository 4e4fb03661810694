"""A detected person's body at the camera: depth mask, parts by metric height, geometry, visibility, descriptor.

The person's pixels are those whose depth point stands on the floor within ``radius_m`` of the person's
vertical axis (through the head top) and nearer to it than to any other detected person's axis: a mask
from depth, so the background and people in front or behind do not leak into the colour histograms. The
colour crop around the person is resampled so the person's full height spans the descriptor's
``siltp_height`` rows, as a dataset crop does (SILTP's pixel radius then means the same at any distance);
depth is sampled on the same grid, and each pixel's part follows from its height above the floor as a
fraction of the person's height: the parts stay the same when the person is near or far, or partly out of
the image. One grid of a few thousand samples per person: everything is vectorised over it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.body.descriptor import BodyDescriptorConfig, body_descriptor
from face_reid_camera.body.observation import BodyGeometry, BodyObservation
from face_reid_camera.body.projection import BodyProjection
from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_camera.people.ground_plane import GroundPlane

__all__ = ["GEOMETRY_BANDS", "BodyConfig", "BodyGrid", "body_grid", "describe_body", "measure_geometry",
           "part_visibility"]

FloatArray = NDArray[np.float64]

# The height band (fractions of the person's height above the floor) each width / depth is measured in.
GEOMETRY_BANDS: dict[str, tuple[float, float]] = {
    "shoulder_width_m": (0.79, 0.85), "torso_width_m": (0.66, 0.76), "torso_depth_m": (0.66, 0.76),
    "hip_width_m": (0.48, 0.56),
}
_MIN_BAND_POINTS = 6  # a width needs at least this many points of its band
_HEAD_SLICE_M = 0.03  # slices of the width profile below the head top
_HEAD_TOP_M = 0.12  # the head's width is the median slice width within this of the top
_SHOULDER_JUMP = 1.6  # the shoulders start at the first slice wider than this x the head
_MAX_HEAD_HEIGHT_M = 0.40
_ROW_MIN_PIXELS = 2  # a grid row shows a part when at least this many of its pixels do
_WIDTH_PERCENTILES = (3.0, 97.0)  # robust extent: outliers at the mask's edge do not count
_DEFAULT_CROP_ROWS = 128  # the person's height in grid rows when the descriptor takes crops as they come
_BOX_ALONG_M = 0.2  # the crop covers this much in front of / behind the body axis (radius_m across it)
_MAX_DEPTH_M = 1000.0  # depth beyond this is not a return
_GEOMETRY_SAMPLES = 2000  # geometry from at most about this many of the person's samples


@dataclass(frozen=True)
class BodyConfig:
    """How a person's body is cut out of the RGB-D frame (the camera node's ``body.*`` parameters)."""

    radius_m: float = param(0.4, "Horizontal reach of a person's pixels around their head's vertical axis (m).",
                            low=0.1, high=1.5)
    floor_margin_m: float = param(0.05, "Pixels less than this above the floor are floor, not feet (m).",
                                  low=0.0, high=0.5)
    min_rows_px: int = param(24, "A person smaller than this in the colour image gets geometry only, no "
                             "appearance descriptor (px).", low=4, high=4096)
    min_visible_fraction: float = param(0.25, "Below this share of the body visible: no appearance "
                                        "descriptor (0..1).", low=0.0, high=1.0)

    def __post_init__(self) -> None:
        validate_fields(self)


@dataclass(frozen=True, eq=False)
class BodyGrid:
    """The person resampled: colour crop (rows, cols, 3), per-sample camera-frame point, mask and part.

    ``edge_rows``: where each part edge of the body axis lies in crop rows (outside [0, rows) when that
    part is out of the image); ``person_rows_px``: the person's height in colour-image rows. ``lateral`` /
    ``along`` / ``height``: each sample's offset from the body axis across and along the line of sight, and
    its height above the floor (m, float32; meaningless where ``mask`` is false, e.g. without depth).
    ``pixel_u`` (cols,) / ``pixel_v`` (rows,): the colour-image coordinates of the grid's sample columns and rows.
    """

    crop: NDArray[np.uint8]
    mask: NDArray[np.bool_]
    parts: NDArray[np.int16]
    lateral: FloatArray
    along: FloatArray
    height: FloatArray
    edge_rows: FloatArray
    person_height_m: float
    person_rows_px: float
    pixel_u: FloatArray
    pixel_v: FloatArray


def _axis_frame(plane: GroundPlane, top_cam: FloatArray, height_m: float) -> tuple[FloatArray, ...]:
    """Foot point on the floor under the head top, up, across-sight and along-sight unit vectors (camera frame)."""
    up = plane.normal
    foot = top_cam - height_m * up
    flat = foot - float(foot @ up) * up  # the camera is at the origin: the horizontal line of sight
    norm = float(np.linalg.norm(flat))
    along = flat / norm if norm > 1e-6 else np.cross(np.array([1.0, 0.0, 0.0]), up)
    along /= np.linalg.norm(along)
    across = np.cross(up, along)
    return foot, up, across, along


def body_grid(
    color_bgr: NDArray[np.uint8], depth_m: NDArray[np.floating], depth_intr: CameraIntrinsics,
    color_intr: CameraIntrinsics, plane: GroundPlane, top_cam: FloatArray, height_m: float,
    other_feet_cam: FloatArray, config: BodyConfig, part_edges: tuple[float, ...], crop_rows: int = 128,
) -> BodyGrid | None:
    """The person's resampled crop (their full height = ``crop_rows`` rows), mask and parts; None when they do
    not show in the colour image.

    ``top_cam``: head top (camera frame, m), ``height_m`` its height above the floor, ``other_feet_cam``
    (m, 3): the floor points under the other detected people's heads (their pixels are theirs).
    """
    foot, up, across, along = _axis_frame(plane, np.asarray(top_cam, dtype=np.float64), height_m)
    r = config.radius_m
    box = _crop_box(color_intr, foot, up, across, along, height_m, r)
    if box is None:
        return None
    cx0, cx1, cy0, cy1, rows_full_px = box
    scale = crop_rows / rows_full_px  # grid rows per colour pixel
    rows = max(2, round((cy1 - cy0) * scale))
    cols = max(2, round((cx1 - cx0) * scale))
    patch = color_bgr[cy0:cy1, cx0:cx1]
    interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    crop = cv2.resize(patch, (cols, rows), interpolation=interpolation)
    # depth at the grid's sample centres (nearest depth pixel; depth registered to colour)
    u = cx0 + (np.arange(cols) + 0.5) * ((cx1 - cx0) / cols) - 0.5
    v = cy0 + (np.arange(rows) + 0.5) * ((cy1 - cy0) / rows) - 0.5
    valid, px, py, pz = _grid_points(depth_m, depth_intr, color_intr, u, v, foot)

    def along_axis(axis: FloatArray) -> NDArray[np.float32]:
        a0, a1, a2 = (np.float32(c) for c in axis)
        out = px * a0
        out += py * a1
        out += pz * a2
        return out

    height, lateral, along_d = along_axis(up), along_axis(across), along_axis(along)
    radial2 = lateral * lateral
    radial2 += along_d * along_d
    mask = valid & (height > config.floor_margin_m) & (height < height_m + 0.1) & (radial2 < r * r)
    others = np.asarray(other_feet_cam, dtype=np.float64).reshape(-1, 3)
    for other in others:  # a pixel nearer to another person's axis is theirs
        d = other - foot
        d -= float(d @ up) * up
        ox, oy = np.float32(d @ across), np.float32(d @ along)
        mask &= radial2 < (lateral - ox) ** 2 + (along_d - oy) ** 2
    below_top = (height_m - height) / height_m
    parts = np.zeros(below_top.shape, dtype=np.int16)
    for edge in part_edges[1:-1]:  # a few edges: comparisons beat a search
        parts += below_top >= edge
    parts[~mask | (below_top > 1.0)] = -1
    edge_points = np.array([foot + (1.0 - e) * height_m * up for e in part_edges])
    edge_rows = (color_intr.project(edge_points)[:, 1] - (cy0 - 0.5)) * scale - 0.5
    return BodyGrid(crop, mask, parts, lateral, along_d, height, edge_rows, float(height_m), rows_full_px, u, v)


def _crop_box(color_intr: CameraIntrinsics, foot: FloatArray, up: FloatArray, across: FloatArray,
              along: FloatArray, height_m: float, r: float) -> tuple[int, int, int, int, float] | None:
    """The colour pixels (x0, x1, y0, y1, clipped to the image) of a box of radius ``r`` around the person's
    axis, and the rows their full height spans; None when they do not show (behind the camera, off the image)."""
    depth_reach = min(r, _BOX_ALONG_M)  # a body is shallow along the line of sight: a narrower crop
    corners = np.array([foot + a * r * across + b * depth_reach * along + z * up
                        for a in (-1.0, 1.0) for b in (-1.0, 1.0) for z in (0.0, height_m)])
    if np.any(corners[:, 2] <= 0.1):
        return None  # (partly) behind or at the camera
    uv = color_intr.project(corners)
    # rows of the full person: the vertical axis projected (head top and foot)
    axis_uv = color_intr.project(np.stack([foot + height_m * up, foot]))
    rows_full_px = float(axis_uv[1, 1] - axis_uv[0, 1])
    if not rows_full_px > 1.0:
        return None
    x0, x1 = math.floor(uv[:, 0].min()), math.ceil(uv[:, 0].max()) + 1
    y0 = math.floor(min(uv[:, 1].min(), axis_uv[0, 1]))
    y1 = math.ceil(max(uv[:, 1].max(), axis_uv[1, 1])) + 1
    cx0, cx1 = max(0, x0), min(color_intr.width, x1)
    cy0, cy1 = max(0, y0), min(color_intr.height, y1)
    if cx1 - cx0 < 2 or cy1 - cy0 < 2:
        return None
    return cx0, cx1, cy0, cy1, rows_full_px


def _grid_points(depth_m: NDArray[np.floating], depth_intr: CameraIntrinsics, color_intr: CameraIntrinsics,
                 u: FloatArray, v: FloatArray, foot: FloatArray) -> tuple[NDArray[np.bool_], ...]:
    """At the grid's sample centres (colour pixels ``u`` x ``v``): where depth is valid, and the camera-frame
    point relative to ``foot`` as three (rows, cols) float32 arrays (float32 broadcasts, no (N, 3) array)."""
    sx, sy = depth_intr.width / color_intr.width, depth_intr.height / color_intr.height
    ud = np.clip(np.rint((u + 0.5) * sx - 0.5), 0, depth_intr.width - 1).astype(np.intp)
    vd = np.clip(np.rint((v + 0.5) * sy - 0.5), 0, depth_intr.height - 1).astype(np.intp)
    z = np.asarray(depth_m[vd[:, None], ud[None, :]], dtype=np.float32)
    valid = (z > 0.0) & (z < _MAX_DEPTH_M)  # NaN and inf fail
    z = np.where(valid, z, np.float32(0.0))  # no NaN / inf in the arithmetic below (those samples stay out)
    xn = ((ud - depth_intr.cx) / depth_intr.fx).astype(np.float32)
    yn = ((vd - depth_intr.cy) / depth_intr.fy).astype(np.float32)
    fx_, fy_, fz_ = (float(c) for c in foot)
    return valid, xn[None, :] * z - np.float32(fx_), yn[:, None] * z - np.float32(fy_), z - np.float32(fz_)


def part_visibility(grid: BodyGrid, part_edges: tuple[float, ...]) -> tuple[float, tuple[float, ...]]:
    """Share of the person's height seen (0..1) in all and per part: rows of the part's expected span
    (by height) that show at least a couple of that part's pixels; rows outside the image count as unseen."""
    n_parts = len(part_edges) - 1
    rows = grid.parts.shape[0]
    labels = grid.parts
    r_idx, c_idx = np.nonzero(labels >= 0)
    counts = np.bincount(r_idx * n_parts + labels[r_idx, c_idx], minlength=rows * n_parts).reshape(rows, n_parts)
    seen_rows = counts >= _ROW_MIN_PIXELS
    per_part = []
    seen_total = 0.0
    for p in range(n_parts):
        start, stop = float(grid.edge_rows[p]), float(grid.edge_rows[p + 1])  # the part's span in crop rows
        span = stop - start
        lo, hi = max(0, math.floor(start)), min(rows, math.ceil(stop))
        seen = float(np.count_nonzero(seen_rows[lo:hi, p])) if hi > lo else 0.0
        per_part.append(min(1.0, seen / span) if span > 0 else 0.0)
        seen_total += min(seen, span)
    full = float(grid.edge_rows[-1] - grid.edge_rows[0])
    return (min(1.0, seen_total / full) if full > 0 else 0.0), tuple(per_part)


def _extent(values: FloatArray) -> float:
    """Robust extent of a few values: between the ``_WIDTH_PERCENTILES`` order statistics (NaN: too few)."""
    n = values.size
    if n < _MIN_BAND_POINTS:
        return float("nan")
    lo = int(_WIDTH_PERCENTILES[0] / 100.0 * (n - 1))
    hi = math.ceil(_WIDTH_PERCENTILES[1] / 100.0 * (n - 1))
    ordered = np.partition(values, (lo, hi))
    return float(ordered[hi] - ordered[lo])


def measure_geometry(grid: BodyGrid, part_edges: tuple[float, ...]) -> BodyGeometry:
    """Widths across the line of sight, torso depth along it and head height from the masked depth samples."""
    h_total = grid.person_height_m
    m = grid.mask
    lat, alo, hgt = grid.lateral[m], grid.along[m], grid.height[m]
    step = max(1, lat.size // _GEOMETRY_SAMPLES)  # a few thousand points measure as well as all of them
    lat, alo, hgt = lat[::step], alo[::step], hgt[::step]
    frac = hgt / h_total

    def band(lo: float, hi: float) -> NDArray[np.bool_]:
        return (frac >= lo) & (frac < hi)

    part_widths = tuple(_extent(lat[band(1.0 - part_edges[p + 1], 1.0 - part_edges[p])])
                        for p in range(len(part_edges) - 1))
    # head height: the width profile in thin slices below the top; the shoulders start where it jumps
    below = h_total - hgt
    head_height = float("nan")
    n_slices = int(_MAX_HEAD_HEIGHT_M / _HEAD_SLICE_M)
    slice_of = np.floor(below / _HEAD_SLICE_M).astype(np.int64)
    near = (slice_of >= 0) & (slice_of < n_slices)
    if np.count_nonzero(near) >= 2 * _MIN_BAND_POINTS:
        order = np.argsort(slice_of[near], kind="stable")
        s, x = slice_of[near][order], lat[near][order]
        starts = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])  # one run per occupied slice
        widths = np.full(n_slices, np.nan)
        widths[s[starts]] = np.maximum.reduceat(x, starts) - np.minimum.reduceat(x, starts)
        top_slices = widths[: max(1, round(_HEAD_TOP_M / _HEAD_SLICE_M))]
        if np.any(np.isfinite(top_slices)):
            head_w = float(np.nanmedian(top_slices))
            wide = np.flatnonzero(np.nan_to_num(widths, nan=0.0) > _SHOULDER_JUMP * max(head_w, 0.05))
            wide = wide[wide >= len(top_slices)]
            if wide.size:
                head_height = float(wide[0] * _HEAD_SLICE_M)
    extents = {name: _extent((alo if name == "torso_depth_m" else lat)[band(*span)])  # depth: along the sight
               for name, span in GEOMETRY_BANDS.items()}
    return BodyGeometry(height_m=h_total, head_height_m=head_height, part_widths_m=part_widths, **extents)


def describe_body(
    color_bgr: NDArray[np.uint8], depth_m: NDArray[np.floating], depth_intr: CameraIntrinsics,
    color_intr: CameraIntrinsics, plane: GroundPlane, top_cam: FloatArray, height_m: float,
    other_feet_cam: FloatArray, config: BodyConfig = BodyConfig(), projection: BodyProjection | None = None,
) -> BodyObservation | None:
    """The :class:`BodyObservation` of one detected person (see :func:`body_grid` for the arguments).

    The appearance descriptor (projected by ``projection``; empty without one) is left out when the person
    spans fewer than ``min_rows_px`` colour rows or less than ``min_visible_fraction`` of them is seen.
    """
    desc_config = projection.descriptor_config if projection is not None else BodyDescriptorConfig()
    edges = desc_config.part_edges
    grid = body_grid(color_bgr, depth_m, depth_intr, color_intr, plane, top_cam, height_m, other_feet_cam,
                     config, edges, desc_config.siltp_height or _DEFAULT_CROP_ROWS)
    if grid is None:
        return None
    visible, per_part = part_visibility(grid, edges)
    geometry = measure_geometry(grid, edges)
    descriptor = np.zeros(0, dtype=np.float32)
    space = ""
    if projection is not None and visible >= config.min_visible_fraction and grid.person_rows_px >= config.min_rows_px:
        # only the columns around the person's pixels (a margin for SILTP's neighbours at both scales)
        cols = np.flatnonzero(grid.mask.any(axis=0))
        if cols.size:
            margin = 2 * desc_config.siltp_radius
            c0, c1 = max(0, int(cols[0]) - margin), min(grid.mask.shape[1], int(cols[-1]) + 1 + margin)
            d = body_descriptor(grid.crop[:, c0:c1], grid.mask[:, c0:c1], desc_config, grid.parts[:, c0:c1])
            descriptor, space = projection.project(d), projection.space
    return BodyObservation(descriptor, space, visible, per_part, geometry)
