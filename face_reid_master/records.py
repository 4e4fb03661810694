"""Plain records the master core consumes and produces (the rclpy-free twins of the messages).

``CameraFrameRecord`` mirrors face_reid_msgs/CameraFrame, ``NamedTrackRecord`` mirrors
face_reid_msgs/NamedTrack. The node converts messages to and from these; the simulator and the
evaluation produce and consume them directly, so the same core runs live and offline.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

STATE_TENTATIVE = 0
STATE_CONFIRMED = 1
STATE_LOST = 2


@dataclass(frozen=True, eq=False)
class BodyRecord:
    """A person's body as a camera described it (the ``body_*`` fields of PersonObservation).

    ``descriptor``: projected appearance (float32, empty = none) in space ``space`` (the camera's
    projection); ``geometry``: ``GEOMETRY_FIELDS`` values (m, NaN = not measured); ``visible_fraction`` and
    ``part_visible`` 0..1 and ``part_widths_m`` (m) per descriptor part (empty: not sent).
    """

    descriptor: NDArray[np.float32]
    space: str
    visible_fraction: float
    geometry: NDArray[np.float32]
    part_visible: NDArray[np.float32] = field(default_factory=lambda: np.zeros(0, np.float32))
    part_widths_m: NDArray[np.float32] = field(default_factory=lambda: np.zeros(0, np.float32))


@dataclass(frozen=True)
class PersonRecord:
    """One person seen by one camera in one frame (world frame, metres); ``body`` None = no body fields."""

    position_world: NDArray[np.float64]
    position_std_m: float = 0.1
    height_m: float = float("nan")
    embedding: NDArray[np.float32] | None = None
    face_score: float = 0.0
    face_quality: float = 0.0
    embedding_space: str = "dlib_resnet_v1"  # which network produced ``embedding`` (embedding_spaces)
    face_eye_distance_px: float = 0.0  # face size in the colour image (0 = unknown)
    body: BodyRecord | None = None


@dataclass(frozen=True)
class CameraFrameRecord:
    """Everything one camera saw at ``stamp_s`` (seconds, the capture time)."""

    camera_id: str
    stamp_s: float
    people: tuple[PersonRecord, ...] = ()
    frame_id: str = "world"


@dataclass(frozen=True)
class NamedTrackRecord:
    """One published track: tracker state + face identity + name."""

    track_id: int
    face_id: int  # 0 = undecided
    name: str
    identity_confidence: float
    face_observations: int
    position_xy: NDArray[np.float64]
    velocity_xy: NDArray[np.float64]
    covariance: NDArray[np.float64]  # 4x4 over (x, y, vx, vy)
    height_m: float
    state: int
    first_seen_s: float
    last_seen_s: float
    cameras: tuple[str, ...] = field(default_factory=tuple)
    identity_evidence: str = ""  # what identified it: "face", "body", "both" ("" = undecided)
