"""The camera network's floor map: fuse the cameras' floor occupancy summaries into an occupancy grid, and save /
load grids as nav2 maps (PGM or PNG + YAML, as nav2's map_server and map_saver read and write them).

Fusion (latest summary per camera, counts summed over cameras per cell; F = floor points, O = obstacle-band
points): a cell is **occupied** (100) when O >= ``min_occupied_points`` and O / (O + F) >= ``min_occupied_fraction``
(a wall's base is seen there far more often than the floor; a person walking through is not), **free** (0) when not
occupied and F >= ``min_free_points``, else **unknown** (-1). Grids follow nav_msgs/OccupancyGrid: row-major,
row = y, the origin is the corner of cell (0, 0), int8 values -1 / 0 / 100.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

from face_reid_camera.common.checks import shown
from face_reid_camera.common.floor_snapshot import FloorOccupancySnapshot
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.robot.frames import load_yaml_mapping

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "CameraMapConfig",
    "CameraMapFusion",
    "OccupancyGridMap",
    "fuse_snapshots",
    "load_nav2_map",
    "save_nav2_map",
]

UNKNOWN, FREE, OCCUPIED = -1, 0, 100
# What nav2's map_saver writes in trinary mode: occupied black, free near-white, unknown grey.
_PIXEL_OCCUPIED, _PIXEL_FREE, _PIXEL_UNKNOWN = 0, 254, 205
# ROS 1's free_thresh: grey 205 (occ 0.19608) stays unknown on reload. nav2's map_saver default 0.25 would turn its
# own unknown grey into free space when map_server loads the file (1 - 205/255 < 0.25).
SAVE_FREE_THRESH = 0.196
SAVE_OCCUPIED_THRESH = 0.65
_MODES = ("trinary", "scale", "raw")


@dataclass(frozen=True)
class OccupancyGridMap:
    """A 2-D occupancy grid: ``data`` (height, width) int8 (-1 unknown, 0 free, 100 occupied, or 1..99), row = y.

    The corner of cell (0, 0) is at (``origin_x_m``, ``origin_y_m``) of ``frame``, the grid turned by
    ``origin_yaw_rad`` about it (nav2 origin [x, y, yaw]).
    """

    data: NDArray[np.int8]
    resolution_m: float
    origin_x_m: float = 0.0
    origin_y_m: float = 0.0
    origin_yaw_rad: float = 0.0
    frame: str = "world"

    def __post_init__(self) -> None:
        arr = np.asarray(self.data)
        if arr.ndim != 2 or arr.size == 0:
            raise ValueError(f"data must be a non-empty 2-D grid, got shape {arr.shape}")
        if arr.size and (arr.min() < -1 or arr.max() > 100):
            raise ValueError("data values must be -1 (unknown) or 0..100")
        object.__setattr__(self, "data", arr.astype(np.int8, copy=False))
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise ValueError(f"resolution_m must be a positive cell side in metres, got {self.resolution_m!r}")
        for name in ("origin_x_m", "origin_y_m", "origin_yaw_rad"):
            if not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    def cell_centres(self, mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """(N, 2) centres (in ``frame``) of the cells where ``mask`` is true (default: the occupied cells)."""
        sel = self.data == OCCUPIED if mask is None else np.asarray(mask, dtype=bool)
        rows, cols = np.nonzero(sel)
        gx, gy = (cols + 0.5) * self.resolution_m, (rows + 0.5) * self.resolution_m
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        return np.stack([self.origin_x_m + c * gx - s * gy, self.origin_y_m + s * gx + c * gy], axis=1)

    def value_at(self, xy: NDArray[np.floating]) -> NDArray[np.int8]:
        """The values at (N, 2) points of ``frame`` (-1 outside the grid)."""
        pts = np.atleast_2d(np.asarray(xy, dtype=np.float64))
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        dx, dy = pts[:, 0] - self.origin_x_m, pts[:, 1] - self.origin_y_m
        col = np.floor((c * dx + s * dy) / self.resolution_m).astype(np.int64)
        row = np.floor((-s * dx + c * dy) / self.resolution_m).astype(np.int64)
        inside = (col >= 0) & (col < self.width) & (row >= 0) & (row < self.height)
        out = np.full(len(pts), UNKNOWN, dtype=np.int8)
        out[inside] = self.data[row[inside], col[inside]]
        return out


@dataclass(frozen=True)
class CameraMapConfig:
    """The fusion rules' thresholds (the map node's parameters)."""

    min_occupied_points: int = param(
        3, "A cell is occupied only with at least this many obstacle-band points over all cameras (count).",
        low=1, high=1_000_000)
    min_occupied_fraction: float = param(
        0.3, "... and when obstacle-band points are at least this fraction of the cell's floor + band points "
        "(0..1; a person walking through, over a floor seen most of the time, stays free).",
        low=0.0, high=1.0, low_open=True)
    min_free_points: int = param(
        3, "A cell that is not occupied is free with at least this many floor points, else unknown (count).",
        low=1, high=1_000_000)
    max_cells: int = param(
        16_000_000, "Refuse to build a grid of more cells than this (count; a camera with a wild pose).",
        low=1, high=1_000_000_000)
    max_cameras: int = param(
        256, "At most this many cameras' summaries are kept; a summary of one more camera is refused (count).",
        low=1, high=100_000)

    def __post_init__(self) -> None:
        validate_fields(self)


def classify(floor: NDArray[np.integer], band: NDArray[np.integer], config: CameraMapConfig) -> NDArray[np.int8]:
    """The fusion rule (module docstring) applied to summed floor / band counts of the same shape."""
    f, o = np.asarray(floor, dtype=np.int64), np.asarray(band, dtype=np.int64)
    occupied = (o >= config.min_occupied_points) & (o >= config.min_occupied_fraction * (o + f))
    out = np.full(f.shape, UNKNOWN, dtype=np.int8)
    out[f >= config.min_free_points] = FREE
    out[occupied] = OCCUPIED
    return out


def fuse_snapshots(snapshots: list[FloorOccupancySnapshot], config: CameraMapConfig,
                   frame: str = "world") -> OccupancyGridMap:
    """One occupancy grid over the union of the snapshots' rectangles (all of one resolution; ValueError else)."""
    if not snapshots:
        raise ValueError("snapshots is empty: no camera has reported its floor yet")
    r = snapshots[0].resolution_m
    for s in snapshots:
        if abs(s.resolution_m - r) > 1e-9 * max(1.0, r):
            raise ValueError(f"camera {s.camera_id!r} reports resolution_m {s.resolution_m} but "
                             f"{snapshots[0].camera_id!r} {r}: set one floor_map_resolution_m on all cameras")
    col0 = [round(s.origin_x_m / r) for s in snapshots]
    row0 = [round(s.origin_y_m / r) for s in snapshots]
    cmin, rmin = min(col0), min(row0)
    cmax = max(c + s.width for c, s in zip(col0, snapshots, strict=True))
    rmax = max(rr + s.height for rr, s in zip(row0, snapshots, strict=True))
    if (cmax - cmin) * (rmax - rmin) > config.max_cells:
        raise ValueError(f"the cameras' summaries span {(cmax - cmin) * r:.1f} x {(rmax - rmin) * r:.1f} m: more "
                         f"than max_cells ({config.max_cells}); is a camera pose wrong?")
    floor = np.zeros((rmax - rmin, cmax - cmin), dtype=np.int64)
    band = np.zeros_like(floor)
    for c, rr, s in zip(col0, row0, snapshots, strict=True):
        floor[rr - rmin:rr - rmin + s.height, c - cmin:c - cmin + s.width] += s.floor_counts
        band[rr - rmin:rr - rmin + s.height, c - cmin:c - cmin + s.width] += s.occupied_counts
    return OccupancyGridMap(classify(floor, band, config), r, cmin * r, rmin * r, 0.0, frame)


class CameraMapFusion:
    """Keeps the latest summary of each camera and fuses them on demand."""

    def __init__(self, config: CameraMapConfig | None = None, frame: str = "world") -> None:
        if config is not None and not isinstance(config, CameraMapConfig):
            raise ValueError(f"config must be a CameraMapConfig, got {type(config).__name__}")
        self.config = config or CameraMapConfig()
        self.frame = frame
        self._latest: dict[str, FloorOccupancySnapshot] = {}

    def update(self, snapshot: FloorOccupancySnapshot) -> bool:
        """Keep ``snapshot`` unless an as-new one of its camera is kept; ValueError for another resolution."""
        others = [s for c, s in self._latest.items() if c != snapshot.camera_id]
        if others and abs(snapshot.resolution_m - others[0].resolution_m) > 1e-9:
            raise ValueError(f"camera {shown(snapshot.camera_id, 64)}: resolution_m {snapshot.resolution_m} differs "
                             f"from the other cameras' {others[0].resolution_m}")
        old = self._latest.get(snapshot.camera_id)
        if old is None and len(self._latest) >= self.config.max_cameras:
            raise ValueError(f"camera {shown(snapshot.camera_id, 64)}: already {len(self._latest)} cameras "
                             f"(max_cameras)")
        if old is not None and snapshot.stamp_s < old.stamp_s:
            return False
        self._latest[snapshot.camera_id] = snapshot
        return True

    @property
    def cameras(self) -> list[str]:
        return sorted(self._latest)

    def grid(self) -> OccupancyGridMap | None:
        """The fused grid, or None before any camera reported."""
        if not self._latest:
            return None
        return fuse_snapshots([self._latest[c] for c in self.cameras], self.config, self.frame)


# ----------------------------------------------------------------------------------------- nav2 map files
def save_nav2_map(grid: OccupancyGridMap, yaml_path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """Write ``grid`` as a nav2 map: ``<stem>.pgm`` (P5, 8 bit, trinary: 0 occupied, 254 free, 205 unknown; top image
    row = highest y) next to the YAML. Returns (yaml path, image path)."""
    ypath = Path(yaml_path)
    if ypath.suffix not in (".yaml", ".yml"):
        ypath = ypath.with_name(ypath.name + ".yaml")
    ipath = ypath.with_suffix(".pgm")
    data = grid.data
    pixels = np.full(data.shape, _PIXEL_UNKNOWN, dtype=np.uint8)
    pixels[(data >= 0) & (data <= round(SAVE_FREE_THRESH * 100))] = _PIXEL_FREE
    pixels[(data >= round(SAVE_OCCUPIED_THRESH * 100)) & (data <= 100)] = _PIXEL_OCCUPIED
    ypath.parent.mkdir(parents=True, exist_ok=True)
    header = f"P5\n# CREATOR: face-reid-map {grid.resolution_m:.3f} m/pix\n{grid.width} {grid.height}\n255\n"
    ipath.write_bytes(header.encode("ascii") + np.ascontiguousarray(pixels[::-1]).tobytes())
    doc = {"image": ipath.name, "mode": "trinary", "resolution": float(grid.resolution_m),
           "origin": [round(float(v), 9) for v in (grid.origin_x_m, grid.origin_y_m, grid.origin_yaw_rad)],
           "negate": 0, "occupied_thresh": SAVE_OCCUPIED_THRESH, "free_thresh": SAVE_FREE_THRESH}
    ypath.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    return ypath, ipath


def _read_pgm(path: Path) -> NDArray[np.float64]:
    """Grey values 0..1 of a P5 (binary) or P2 (ASCII) PGM; ValueError for anything else."""
    raw = path.read_bytes()
    magic = raw[:2]
    if magic not in (b"P5", b"P2"):
        raise ValueError(f"{path}: not a PGM (magic {magic!r}, want P5 or P2)")
    fields: list[bytes] = []
    pos = 2
    while len(fields) < 3:  # width, height, maxval; '#' comments run to the end of the line
        while pos < len(raw) and raw[pos:pos + 1].isspace():
            pos += 1
        if pos >= len(raw):
            raise ValueError(f"{path}: PGM header is cut short")
        if raw[pos:pos + 1] == b"#":
            end = raw.find(b"\n", pos)
            pos = len(raw) if end < 0 else end + 1
            continue
        start = pos
        while pos < len(raw) and not raw[pos:pos + 1].isspace():
            pos += 1
        fields.append(raw[start:pos])
    try:
        width, height, maxval = (int(f) for f in fields)
    except ValueError:
        raise ValueError(f"{path}: PGM header has non-numeric size or maxval {fields!r}") from None
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise ValueError(f"{path}: PGM size {width}x{height} / maxval {maxval} is invalid")
    n = width * height
    if magic == b"P5":
        pos += 1  # exactly one whitespace byte after maxval
        dtype = np.uint8 if maxval < 256 else np.dtype(">u2")
        need = n * np.dtype(dtype).itemsize
        if len(raw) - pos < need:
            raise ValueError(f"{path}: PGM pixel data is cut short ({len(raw) - pos} of {need} bytes)")
        values = np.frombuffer(raw, dtype=dtype, count=n, offset=pos).astype(np.float64)
    else:
        try:
            values = np.array([int(t) for t in raw[pos:].split()[:n + 1]], dtype=np.float64)
        except ValueError:
            raise ValueError(f"{path}: PGM (P2) pixel data is not all integers") from None
        if len(values) != n:
            raise ValueError(f"{path}: PGM (P2) has {len(values)} pixel values, want {n}")
    if values.max(initial=0) > maxval:
        raise ValueError(f"{path}: PGM pixel values exceed maxval {maxval}")
    return values.reshape(height, width) / maxval


def _read_image(path: Path, mode: str) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(shade 0..1 per pixel as nav2 computes it, opaque mask) of a PGM or any image cv2 reads (PNG, BMP...)."""
    if path.suffix.lower() == ".pgm":
        shade = _read_pgm(path)
        return shade, np.ones(shade.shape, dtype=bool)
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path}: cannot read the map image (missing, or not an image cv2 reads)")
    scale = 65535.0 if img.dtype == np.uint16 else 255.0
    img = img.astype(np.float64) / scale
    if img.ndim == 2:
        return img, np.ones(img.shape, dtype=bool)
    colour, alpha = img[:, :, :3], (img[:, :, 3] if img.shape[2] == 4 else None)
    channels = [colour[:, :, k] for k in range(colour.shape[2])]
    if alpha is not None and mode == "trinary":
        channels.append(alpha)  # nav2 averages opacity in with the colour in trinary mode
    shade = np.mean(channels, axis=0)
    return shade, (alpha >= 1.0) if alpha is not None else np.ones(shade.shape, dtype=bool)


def load_nav2_map(yaml_path: str | os.PathLike[str], frame: str = "map") -> OccupancyGridMap:
    """Read a nav2 map YAML and its image (path relative to the YAML) the way nav2's map_server does: occ =
    1 - shade (shade when ``negate``); trinary / scale / raw modes. ValueError names what is wrong."""
    ypath = Path(yaml_path)
    doc = load_yaml_mapping(ypath, ("image", "resolution", "origin"), "map YAML")
    try:
        resolution = float(doc["resolution"])
        origin = [float(v) for v in doc["origin"]]
        negate = bool(int(doc.get("negate", 0)))
        occ_th = float(doc.get("occupied_thresh", SAVE_OCCUPIED_THRESH))
        free_th = float(doc.get("free_thresh", SAVE_FREE_THRESH))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{ypath}: resolution, origin [x, y, yaw], negate and the thresholds must be numbers "
                         f"({exc})") from exc
    mode = str(doc.get("mode", "trinary")).lower()
    if mode not in _MODES:
        raise ValueError(f"{ypath}: mode must be one of {', '.join(_MODES)}, got {mode!r}")
    if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
        raise ValueError(f"{ypath}: origin must be [x, y, yaw] (finite numbers), got {doc['origin']!r}")
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"{ypath}: resolution must be a positive number of metres per pixel, got {resolution!r}")
    if not 0.0 <= free_th <= occ_th <= 1.0:
        raise ValueError(f"{ypath}: need 0 <= free_thresh ({free_th}) <= occupied_thresh ({occ_th}) <= 1")
    image = Path(str(doc["image"]))
    ipath = image if image.is_absolute() else ypath.parent / image
    try:
        shade, opaque = _read_image(ipath, mode)
    except OSError as exc:
        raise ValueError(f"{ypath}: cannot read its image {ipath}: {exc}") from exc
    occ = shade if negate else 1.0 - shade
    if mode == "raw":
        value = np.round(shade * 255.0)
        data = np.where((value >= 0) & (value <= 100), value, UNKNOWN).astype(np.int8)
    else:
        data = np.full(shade.shape, UNKNOWN, dtype=np.int8)
        if mode == "scale":
            mid = np.rint((occ - free_th) / max(occ_th - free_th, 1e-12) * 100.0)
            data = np.clip(mid, 0, 100).astype(np.int8)
        data[occ < free_th] = FREE
        data[occ > occ_th] = OCCUPIED
        if mode == "scale":
            data[~opaque] = UNKNOWN
    return OccupancyGridMap(data[::-1].copy(), resolution, origin[0], origin[1], origin[2], frame)
