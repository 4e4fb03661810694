"""What the camera reports about a person's body: appearance on the wire, depth geometry, visibility.

The core twin of the ``body_*`` fields of face_reid_msgs/PersonObservation. Geometry comes from the
person's depth points (no skeleton): metric lengths that do not depend on the clothes or the light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["GEOMETRY_FIELDS", "GEOMETRY_MSG_FIELDS", "BodyGeometry", "BodyObservation"]

# The geometric features in vector order (metres; NaN = not measured, e.g. that part is hidden).
GEOMETRY_FIELDS = ("height_m", "head_height_m", "shoulder_width_m", "torso_width_m", "torso_depth_m",
                   "hip_width_m")
# The face_reid_msgs/PersonObservation field of each of them (the height is the detection's own height_m).
GEOMETRY_MSG_FIELDS = tuple(name if name == "height_m" else f"body_{name}" for name in GEOMETRY_FIELDS)


@dataclass(frozen=True)
class BodyGeometry:
    """Metric body measures from the depth points (NaN = not measured).

    ``height_m``: head top above the floor. ``head_height_m``: head top down to the shoulders.
    ``shoulder_width_m`` / ``torso_width_m`` / ``hip_width_m``: horizontal extent across the line of sight
    at shoulder / chest / hip height (a side view gives the body's depth instead: the metric learns that).
    ``torso_depth_m``: extent of the visible torso surface along the line of sight. ``part_widths_m``:
    the extent across the line of sight of each descriptor part (head/shoulders, torso, upper, lower legs).
    """

    height_m: float
    head_height_m: float = float("nan")
    shoulder_width_m: float = float("nan")
    torso_width_m: float = float("nan")
    torso_depth_m: float = float("nan")
    hip_width_m: float = float("nan")
    part_widths_m: tuple[float, ...] = ()

    def vector(self) -> NDArray[np.float32]:
        """The ``GEOMETRY_FIELDS`` values in order, float32."""
        return np.array([getattr(self, name) for name in GEOMETRY_FIELDS], dtype=np.float32)


@dataclass(frozen=True, eq=False)
class BodyObservation:
    """One person's body in one frame.

    ``descriptor``: the projected appearance descriptor (:mod:`face_reid_camera.body.projection`), float32,
    in space ``space``; empty when the body was too little visible to describe. ``visible_fraction`` (0..1):
    the share of the person's height from head to feet that the camera saw (image border and occluders
    cut it); ``part_visible``: the same per descriptor part. ``geometry``: see :class:`BodyGeometry`.
    """

    descriptor: NDArray[np.float32]
    space: str
    visible_fraction: float
    part_visible: tuple[float, ...]
    geometry: BodyGeometry
