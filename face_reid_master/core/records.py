"""What the master core counts and what it tells its caller about each frame."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import NewType

from face_reid_master.identity.records import IdentityEvent
from face_reid_master.tracking.interface import TrackerId

__all__ = ["FrameOutcome", "MasterStats", "PublicId"]

PublicId = NewType("PublicId", int)  # a track as the master publishes it: the tracker's id until a swap splits it


@dataclass
class MasterStats:
    """Counters of everything the core accepted, rejected or decided (logged by the node)."""

    frames_received: int = 0
    frames_applied: int = 0
    frames_rejected_unknown_camera: int = 0
    frames_rejected_stale: int = 0
    frames_rejected_future: int = 0
    frames_rejected_bad_stamp: int = 0
    frames_rejected_tracker_late: int = 0
    frames_rejected_too_many_people: int = 0
    frames_rejected_camera_rate: int = 0
    frames_future_clamped: int = 0  # stamped ahead of the master's clock (within max_stamp_future_s): applied at it
    clock_jumps_back: int = 0  # the master's own clock went back: the tracker started afresh
    detections_received: int = 0
    detections_rejected_position: int = 0
    embeddings_used: int = 0
    embeddings_rejected_length: int = 0
    embeddings_rejected_space: int = 0
    embeddings_rejected_nonfinite: int = 0
    embeddings_rejected_norm: int = 0  # lengths no embedder of the space produces
    embeddings_skipped_quality: int = 0
    bodies_received: int = 0  # detections with well-formed body fields
    bodies_rejected_malformed: int = 0  # body fields with NaN / Inf appearance or out-of-range visibility
    bodies_rejected_space: int = 0  # descriptors of another projection than the body metric's
    faces_created: int = 0
    faces_reidentified: int = 0
    faces_released: int = 0
    faces_released_swapped: int = 0  # of which: the track was swapped onto someone else (published under a new id)
    faces_pruned: int = 0
    faces_evicted: int = 0  # unnamed faces forgotten to keep max_faces (least recently seen first)
    faces_refused_cap: int = 0  # new faces not learned: max_faces reached and every face named or on a track
    faces_refused_no_id: int = 0  # new faces not learned: their id could not be reserved in the store (writes fail)
    embeddings_rejected_degenerate: int = 0  # constant rows (all zero, ...): no embedder produces them
    store_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class FrameOutcome:
    """What :meth:`MasterCore.process_frame` did with one frame (``reason`` and its short ``code``, e.g.
    ``stale_stamp``, when rejected: the node counts rejections by code). Track ids are the tracker's
    (:data:`TrackerId`; ``MasterCore.public_id`` gives the published one) except in ``identity_events``, whose
    ``track_id`` is the published :data:`PublicId`."""

    accepted: bool
    reason: str = ""
    code: str = ""
    track_of_person: dict[int, TrackerId] = field(default_factory=dict)  # index in frame.people -> tracker id
    tracks_created: tuple[TrackerId, ...] = ()
    tracks_deleted: tuple[TrackerId, ...] = ()
    identity_events: tuple[IdentityEvent, ...] = ()  # track_id: the PublicId
    notices: tuple[str, ...] = ()  # things the node should log once (e.g. a camera of another embedder space)
