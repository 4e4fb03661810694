"""Rigid 2-D transforms (:class:`PlanarTransform`: the world -> map transform of a robot's map, the cameras' pose
corrections of face-reid-calibrate) and the world -> map transform's file.

``p_map = R(yaw) p_world + (x, y)``: what ``face-reid-align-map`` writes and ``face-reid-goto`` (and the
people outputs) read. Heights are unchanged (both frames have z up from the same floor).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

__all__ = ["PlanarTransform", "load_world_to_map", "load_yaml_mapping", "save_world_to_map"]


@dataclass(frozen=True)
class PlanarTransform:
    """A rigid 2-D transform: rotate by ``yaw_rad`` about z, then translate by (``x_m``, ``y_m``)."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "yaw_rad"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")

    @classmethod
    def identity(cls) -> PlanarTransform:
        return cls(0.0, 0.0, 0.0)

    @property
    def matrix(self) -> NDArray[np.float64]:
        """The 3x3 homogeneous matrix."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.array([[c, -s, self.x_m], [s, c, self.y_m], [0.0, 0.0, 1.0]])

    @classmethod
    def from_matrix(cls, m: NDArray[np.floating]) -> PlanarTransform:
        return cls(float(m[0, 2]), float(m[1, 2]), math.atan2(float(m[1, 0]), float(m[0, 0])))

    def apply(self, xy: NDArray[np.floating]) -> NDArray[np.float64]:
        """Transform (N, 2) or (2,) points (extra columns, e.g. z, are kept unchanged)."""
        pts = np.asarray(xy, dtype=np.float64)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts).copy()
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        x, y = pts[:, 0].copy(), pts[:, 1].copy()
        pts[:, 0] = c * x - s * y + self.x_m
        pts[:, 1] = s * x + c * y + self.y_m
        return pts[0] if single else pts

    def rotate(self, vectors: NDArray[np.floating]) -> NDArray[np.float64]:
        """Rotate (N, 2) or (2,) direction vectors (velocities): no translation."""
        return PlanarTransform(0.0, 0.0, self.yaw_rad).apply(vectors)

    def inverse(self) -> PlanarTransform:
        return PlanarTransform.from_matrix(np.linalg.inv(self.matrix))

    def compose(self, inner: PlanarTransform) -> PlanarTransform:
        """``self`` after ``inner`` (apply ``inner`` first)."""
        return PlanarTransform.from_matrix(self.matrix @ inner.matrix)


def save_world_to_map(path: str | os.PathLike[str], transform: PlanarTransform, *, world_frame: str = "world",
                      map_frame: str = "map", residual_m: float | None = None, note: str = "") -> None:
    """Write the world -> map transform as YAML (yaw in degrees, for people who edit it by hand)."""
    doc: dict[str, object] = {
        "world_frame": world_frame, "map_frame": map_frame,
        "x_m": round(transform.x_m, 6), "y_m": round(transform.y_m, 6),
        "yaw_deg": round(math.degrees(transform.yaw_rad), 6),
    }
    if residual_m is not None:
        doc["residual_m"] = round(float(residual_m), 6)
    if note:
        doc["note"] = note
    Path(path).write_text("# p_map = R(yaw) p_world + (x, y); written by face-reid-align-map\n"
                          + yaml.safe_dump(doc, sort_keys=False))


def load_yaml_mapping(path: str | os.PathLike[str], required: tuple[str, ...], what: str) -> dict[str, Any]:
    """A YAML file's top-level mapping with the ``required`` keys; ValueError names the file (``what`` it is
    meant to be) and what is wrong: unreadable, not a mapping, missing keys."""
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"cannot read the {what} {p}: {exc}") from exc
    if not isinstance(doc, dict):
        raise ValueError(f"{p}: a {what} is a mapping with {', '.join(required)}")
    missing = [k for k in required if k not in doc]
    if missing:
        raise ValueError(f"{p}: missing {', '.join(missing)}")
    return doc


def load_world_to_map(path: str | os.PathLike[str]) -> tuple[PlanarTransform, str, str]:
    """Read a file written by :func:`save_world_to_map`: (transform, world_frame, map_frame). ValueError names
    what is wrong with it."""
    p = Path(path)
    doc = load_yaml_mapping(p, ("x_m", "y_m", "yaw_deg"), "world->map transform")
    try:
        transform = PlanarTransform(float(doc["x_m"]), float(doc["y_m"]), math.radians(float(doc["yaw_deg"])))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{p}: x_m, y_m and yaw_deg must be finite numbers ({exc})") from exc
    world_frame, map_frame = str(doc.get("world_frame", "world")), str(doc.get("map_frame", "map"))
    if not world_frame or not map_frame:
        raise ValueError(f"{p}: world_frame and map_frame must be non-empty")
    return transform, world_frame, map_frame
