"""Records exchanged with the face identity layer: identity events, learned faces, counters."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int
from face_reid_master.identity.evidence import Evidence

__all__ = ["MAX_FACE_ID", "IdentityEvent", "IdentityEventKind", "IdentityStats", "LearnedFace", "check_face_id"]

F32Array = npt.NDArray[np.float32]

MAX_FACE_ID = 2**63 - 1  # the face store keeps ids as SQLite INTEGER (signed 64-bit)


def check_face_id(value: object) -> int:
    """A face id as an int in [1, MAX_FACE_ID]; ValueError with a clear reason (a request's uint64 can be larger)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise ValueError(f"face id must be an integer, got {type(value).__name__}")
    if not 1 <= int(value) <= MAX_FACE_ID:
        raise ValueError(f"face id must be between 1 and {MAX_FACE_ID}, got {int(value)}")
    return int(value)


class IdentityEventKind(str, enum.Enum):
    """What happened to a track's face identity."""

    ASSIGNED_KNOWN = "assigned_known"  # the track was recognised as a learned face (re-identification)
    NEW_FACE = "new_face"  # the track is an unknown person: a new face id was created for it
    RELEASED = "released"  # the track died: its face goes back to face_list (assignable again)
    SWAPPED = "swapped"  # the track's faces stopped matching its face (a tracker swap): face back to face_list,
    # the track is classified afresh


@dataclass(frozen=True)
class IdentityEvent:
    """One identity change, returned by :meth:`~face_reid_master.identity.algorithm1.IdentityManagerBase.step`."""

    kind: IdentityEventKind
    track_id: int
    face_id: int
    stamp_s: float
    confidence: float  # posterior (Bayes) or vote fraction (threshold) when the decision was made
    since_s: float | None = None  # SWAPPED: stamp of the first observation that was not the face's person
    evidence: str = Evidence.FACE  # ASSIGNED_KNOWN / NEW_FACE: what decided it (the face or another cue's kind)


@dataclass
class LearnedFace:
    """A learned face for export/import (persistent memory): id, bounded feature set, optional name."""

    face_id: int
    features: F32Array  # (k, embedding_dim) float32, k >= 1
    name: str | None = None
    created_s: float = 0.0
    last_seen_s: float = 0.0
    n_observations: int = 0

    def __post_init__(self) -> None:
        self.face_id = check_int("LearnedFace.face_id", self.face_id, 1)
        feats = np.asarray(self.features)
        if feats.ndim != 2 or feats.shape[0] < 1 or feats.shape[1] < 1:
            raise ValueError(f"LearnedFace.features must have shape (k >= 1, dim), got {feats.shape}")
        if not np.issubdtype(feats.dtype, np.floating):
            raise ValueError(f"LearnedFace.features must be floating point, got {feats.dtype}")
        if not np.all(np.isfinite(feats)):
            raise ValueError(f"LearnedFace {self.face_id}: features contain NaN or Inf")
        self.features = np.ascontiguousarray(feats, dtype=np.float32)
        if self.name is not None and not isinstance(self.name, str):
            raise ValueError(f"LearnedFace.name must be a str or None, got {self.name!r}")
        for attr in ("created_s", "last_seen_s"):
            value = float(getattr(self, attr))
            if not math.isfinite(value):
                raise ValueError(f"LearnedFace.{attr} must be finite")
            setattr(self, attr, value)
        if int(self.n_observations) < 0:
            raise ValueError("LearnedFace.n_observations must be >= 0")
        self.n_observations = int(self.n_observations)


@dataclass
class IdentityStats:
    """Counters for diagnostics (the node publishes/logs them)."""

    steps: int = 0
    observations_received: int = 0
    observations_ignored_dead_track: int = 0
    assigned_known: int = 0
    new_faces: int = 0
    released: int = 0
    sinkhorn_runs: int = 0
    sinkhorn_not_converged: int = 0
    last_sinkhorn_iterations: int = 0
    shortlist_searches: int = 0
    faces_forgotten: int = 0
    observations_not_learned_inconsistent: int = 0
    observations_not_learned_uncertain: int = 0  # faces of tracks decided below learn_confidence
    cue_observations_not_learned_uncertain: int = 0  # other cues' (bodies) of tracks decided below it
    swaps_released: int = 0  # tracks released as someone else: the swap guard, or a crossing more likely than not
    body_observations: int = 0
    assigned_by_body: int = 0
    tracks_restarted: int = 0  # unidentified tracks classified afresh: a stray made their evidence another person's
    decisions_excluded_co_seen: int = 0  # decisions not taken (per step): the face's track was seen alongside the track
    lent_faces_taken: int = 0  # faces of LOST tracks given to another track (the person came back as it)
