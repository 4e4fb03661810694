"""Records the tracker takes and returns: detections in, snapshots / per-frame results / counters out."""

from __future__ import annotations

import enum
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

__all__ = ["Detection", "FrameStatus", "TrackSnapshot", "TrackState", "TrackerStats", "UpdateResult"]

FloatArray = NDArray[np.float64]


class TrackState(enum.IntEnum):
    """Lifecycle state of a track."""

    TENTATIVE = 0
    CONFIRMED = 1
    LOST = 2
    DELETED = 3


class FrameStatus(enum.Enum):
    """What the tracker did with one camera frame (or :meth:`Tracker.advance` call)."""

    APPLIED = "applied"  # in stamp order
    APPLIED_LATE = "applied_late"  # older than the clock, within max_detection_delay_s
    REJECTED_LATE = "rejected_late"
    REJECTED_FUTURE = "rejected_future"
    ADVANCED = "advanced"  # clock moved by advance(), no detections


@dataclass(frozen=True, slots=True)
class Detection:
    """One person detection of a camera frame, in the world frame (metres).

    Not validated (inputs come validated from MasterCore): ``position_xy`` is a finite (2,)
    ground-plane position, ``position_std_m`` a finite isotropic std > 0, ``height_m`` the head/top
    height above the floor (nan if unknown).
    """

    position_xy: FloatArray
    position_std_m: float = 0.1
    height_m: float = float("nan")


@dataclass(frozen=True)
class TrackSnapshot:
    """Read-only view of one track at ``stamp_s`` (state predicted to that time).

    ``covariance`` is the 4x4 covariance of (x, y, vx, vy).  ``cameras``: cameras that detected it
    within ``camera_window_s`` of the clock.
    """

    track_id: int
    state: TrackState
    position_xy: FloatArray
    velocity_xy: FloatArray
    covariance: FloatArray
    stamp_s: float
    created_s: float
    last_seen_s: float
    hits: int
    cameras: frozenset[str]
    height_m: float

    @property
    def position_covariance(self) -> FloatArray:
        return self.covariance[:2, :2]


@dataclass(frozen=True)
class UpdateResult:
    """What one ``update``/``advance`` call did.

    ``associations``: (track_id, detection index in the input) pairs, including the detections that
    created new tracks.  ``created`` / ``confirmed`` / ``lost`` / ``recovered`` / ``deleted``: track
    ids that changed state in this call.  ``rejected_detections``: input indices dropped at the
    ``max_tracks`` limit.  ``suppressed_detections``: unassociated detections that started no track
    because they lie within ``min_person_separation_m`` of a track (whose person was already matched:
    a duplicate detection).  ``clock_resync``: this frame re-based the clock after a run of rejected
    frames (on a backward jump all tracks are deleted first).  ``swaps``: pairs of tracks this frame's association
    could have given each other's person, with the probability that it did (crossings). ``strays``: tracks that may
    have taken the detection of a person they were not following, with that probability.
    """

    stamp_s: float
    camera_id: str
    status: FrameStatus
    associations: tuple[tuple[int, int], ...] = ()
    created: tuple[int, ...] = ()
    confirmed: tuple[int, ...] = ()
    lost: tuple[int, ...] = ()
    recovered: tuple[int, ...] = ()
    deleted: tuple[int, ...] = ()
    rejected_detections: tuple[int, ...] = ()
    suppressed_detections: tuple[int, ...] = ()
    clock_resync: bool = False
    swaps: tuple[tuple[int, int, float], ...] = ()  # (track id, track id, probability this frame swapped them)
    strays: tuple[tuple[int, float], ...] = ()  # (track id, probability its detection is someone else)

    @property
    def accepted(self) -> bool:
        return self.status in (FrameStatus.APPLIED, FrameStatus.APPLIED_LATE)

    def track_of_detection(self) -> dict[int, int]:
        """Detection index -> track id for this frame."""
        return {det: tid for tid, det in self.associations}


@dataclass
class TrackerStats:
    """Counters since construction (``Tracker.stats`` returns a copy)."""

    frames_processed: int = 0
    frames_out_of_order: int = 0  # processed although older than the clock (within the bound)
    frames_rejected_late: int = 0
    frames_rejected_future: int = 0
    clock_resyncs: int = 0
    detections_received: int = 0
    detections_associated: int = 0
    detections_dropped_track_limit: int = 0
    detections_suppressed_near_track: int = 0
    tracks_merged: int = 0  # tentative duplicates dropped next to a confirmed track (also in deleted)
    tracks_created: int = 0
    tracks_confirmed: int = 0
    tracks_deleted: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}
