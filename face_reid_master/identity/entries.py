"""What the master keeps per learned face and per live track (one record each), and the observations it queues."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.evidence import CueChunk, Evidence

__all__ = [
    "Chunk", "FaceEntry", "TrackRecord", "Vote", "checked_observations", "eye_rows", "rows_of",
]

FloatArray = npt.NDArray[np.float64]
F32Array = npt.NDArray[np.float32]


@dataclass
class FaceEntry:
    """A learned face: its bank slot, metadata, and the live track carrying it (None = in face_list)."""

    face_id: int
    slot: int
    name: str | None
    created_s: float
    last_seen_s: float
    n_observations: int
    track_id: int | None = None


@dataclass(frozen=True, slots=True)
class Vote:
    """One observation's vote of the threshold baseline: a face id (0 = new person) and its distance."""

    face_id: int
    distance: float


class Chunk(NamedTuple):
    """Observations of one track queued by one ``add_observations`` call of the identity manager: the
    embeddings (K, dim), their eye distances (px; None = unknown), the stamp (s) and the camera."""

    embeddings: F32Array
    eye_px: FloatArray | None
    stamp_s: float
    source: str


@dataclass(eq=False)
class TrackRecord:
    """Everything the master keeps about one live track, in one place (track_list of Algorithm 1 holds them;
    :meth:`~face_reid_master.identity.track_list.TrackList.remove` drops it whole). Keyed by the tracker's id;
    the tracker keeps the kinematics under that id (the handle), the master publishes the track as
    ``public_id``."""

    track_id: int  # the tracker's id: the kinematics handle (face_reid_master.tracking.interface.TrackerId)
    slot: int | None = None  # bank slot buffering observed features while unassigned (track.face_images)
    n_observations: int = 0
    first_seen_s: float = 0.0
    last_seen_s: float = 0.0
    face_id: int | None = None
    confidence: float = 0.0
    votes: list[Vote] = field(default_factory=list)  # threshold baseline only
    inconsistent: list[Chunk] = field(default_factory=list)  # identified: the current run of faces not its face's
    evidence: str = Evidence.NONE  # identified: what decided it (an evidence.Evidence or another cue's kind)
    new_face: bool = False  # identified: its decision created the face (a person not known before)
    face_chunks: list[Chunk] = field(default_factory=list)  # face observations waiting for the next step
    cue_queue: dict[str, list[CueChunk]] = field(default_factory=dict)  # other cues' observations, per cue kind
    bayes_row: int = 0  # Bayes method: its row of the posterior table while unassigned (0: none)
    public_id: int = 0  # the id it is published under (core.records.PublicId): track_id until a swap split it
    public_since_s: float | None = None  # when the current public id began (None: when the tracker made it)
    face_observations: int = 0  # face embeddings the master used since it got its public id
    crossed: dict[int, float] = field(default_factory=dict)  # track id (NOBODY: a stray) -> probability of a swap
    person_since_s: float = 0.0  # it has followed one person since (first sighting, or a crossing past one half)
    not_faces: set[int] = field(default_factory=set)  # faces of tracks seen alongside it (co_sightings)

    def __post_init__(self) -> None:
        if not self.public_id:
            self.public_id = self.track_id

    def give(self, face_id: int, confidence: float, evidence: str, new: bool) -> None:
        """The track carries face ``face_id`` from now on, decided by ``evidence`` (``new``: it created it)."""
        self.face_id, self.confidence, self.evidence, self.new_face = face_id, float(confidence), evidence, new

    def teaches(self, learn_confidence: float) -> bool:
        """Identified: whether what it shows (faces, bodies) joins its face (not after a known-face decision below
        ``learn_confidence``)."""
        return self.new_face or self.evidence != Evidence.FACE or self.confidence >= learn_confidence

    def person_changed(self) -> None:
        """A crossing or stray made another person likelier than not on the track: it follows them from its last
        sighting on, and what it was seen alongside before says nothing of them."""
        self.person_since_s = self.last_seen_s
        self.not_faces.clear()

    def unassign(self) -> None:
        """The track holds no face any more: it is classified afresh from its next observations."""
        self.face_id, self.confidence, self.evidence = None, 0.0, Evidence.NONE
        self.votes.clear()
        self.n_observations = 0


def rows_of(chunks: list[Chunk]) -> F32Array:
    """The embeddings of a track's queued chunks, stacked."""
    return chunks[0].embeddings if len(chunks) == 1 else np.concatenate([c.embeddings for c in chunks])


def eye_rows(chunks: list[Chunk]) -> FloatArray:
    """Eye distance (px) of every row of a track's queued chunks (0 = unknown)."""
    return np.concatenate([c.eye_px if c.eye_px is not None else np.zeros(c.embeddings.shape[0]) for c in chunks])


def checked_observations(track_id: int, embeddings: npt.ArrayLike, eye_px: npt.ArrayLike | None, source: object,
                         dim: int) -> tuple[F32Array, FloatArray | None] | None:
    """Face embeddings (K, dim) of a track and their eye distances as the identity manager queues them
    (C-contiguous float32, float64); None for K = 0; ValueError naming what is wrong (shape, dtype, NaN / Inf,
    eye distances per row, a source that is not a str)."""
    emb = np.asarray(embeddings)
    if emb.ndim != 2 or emb.shape[1] != dim:
        raise ValueError(f"embeddings must have shape (K, {dim}), got {emb.shape} for track {track_id}")
    if not (np.issubdtype(emb.dtype, np.floating) or np.issubdtype(emb.dtype, np.integer)) or (
        emb.dtype == np.bool_
    ):
        raise ValueError(f"embeddings must be a real numeric array, got dtype {emb.dtype}")
    if not np.all(np.isfinite(emb)):
        raise ValueError(f"embeddings of track {track_id} contain NaN or Inf")
    if emb.shape[0] == 0:
        return None
    eye = None
    if eye_px is not None:
        eye = np.asarray(eye_px, dtype=np.float64).reshape(-1)
        if eye.shape != (emb.shape[0],):
            raise ValueError(f"eye_px must have one value per embedding ({emb.shape[0]}), got {eye.shape}")
    if not isinstance(source, str):
        raise ValueError(f"source must be a str, got {type(source).__name__}")
    return np.ascontiguousarray(emb, dtype=np.float32), eye
