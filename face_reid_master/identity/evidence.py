"""The cues that identify a track, and the interface every cue but the face implements.

A track is identified by its face (Algorithm 1: the classification method learns faces, creates them and
decides between them) or, while it shows no face, by another cue that recognises the person of a learned face:
the body (:mod:`~face_reid_master.identity.body_identification`), or any cue added beside it (a badge, gait,
voice). Such a cue is an :class:`EvidenceSource`: the master core reads its observation off each detection
(:meth:`EvidenceSource.read`), the identity layer queues it in the track's record and, at each step, hands the
queued observations over (:meth:`EvidenceSource.observe`), asks which faceless tracks the cue decides
(:meth:`EvidenceSource.decide`), and tells it when a track got a face or went and when a face was forgotten.
Adding a cue is therefore one module with a class of this shape plus the message field it reads.

What identified a track (published as ``identity_evidence``) is the face, a cue's ``kind`` or "both", a cue's
decision that the track's own face then confirmed: the built-in ones are :class:`Evidence`; a new cue's kind is
a constant of its own module.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

__all__ = ["CueChunk", "Cues", "Evidence", "EvidenceSource", "TrackView"]

F32Array = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]


class Evidence(enum.StrEnum):
    """What identified a track (the strings are the published ``identity_evidence`` and the events' evidence)."""

    NONE = ""  # undecided
    FACE = "face"  # its face (the classification method)
    BODY = "body"  # its body appearance and head height (a faceless track)
    BOTH = "both"  # a cue other than the face decided, then its own face agreed


class CueChunk(NamedTuple):
    """Observations of one cue on one track queued for the identity step: values (k, r), stamp (s), camera and
    head heights (k,; None = unknown)."""

    values: F32Array
    stamp_s: float
    source: str
    heights: FloatArray | None


class TrackView(Protocol):
    """What a cue reads of a track's record (:class:`~face_reid_master.identity.entries.TrackRecord`)."""

    track_id: int
    face_id: int | None  # None: not identified
    slot: int | None  # not None: the track shows a face and is being classified by it


class EvidenceSource(Protocol):
    """A cue that recognises the person of a learned face on a track that shows no face (see the module doc)."""

    kind: str  # its name: what a track it decides is identified by (the key of its queue in each track's record)

    def read(self, person: Any, detection: int, detections: Any) -> F32Array | None:
        """Its observation (1, r) on one associated detection (``person``: the frame's PersonRecord; row
        ``detection`` of the validated frame ``detections``); None: not observed."""

    def observe(self, queued: Sequence[tuple[TrackView, list[CueChunk]]], face_ids: list[int]) -> None:
        """The observations queued since the last step: an identified track's describe its face's person, a
        faceless track's are weighed against the learned faces ``face_ids``."""

    def decide(self, available: list[int], stamp: float, alike: Callable[[int, list[int]], list[bool]]
               ) -> list[tuple[int, int, float]]:
        """(track id, face id, confidence) of the faceless tracks decided now, among ``available`` faces (those of
        face_list); ``alike(a, others)``: which of ``others`` are face a's person."""

    def track_identified(self, track_id: int, face_id: int) -> None:
        """The track got face ``face_id`` (by any cue): what it gathered describes that face's person now."""

    def forget_track(self, track_id: int) -> None:
        """The track was deleted, or identified by a decision that teaches nothing: what it gathered goes."""

    def forget_face(self, face_id: int) -> None:
        """The face was forgotten."""


class Cues:
    """The registry of the cues besides the face, in the order they decide (the body first): each kind once."""

    def __init__(self, sources: list[EvidenceSource]) -> None:
        self.sources = sources
        self.kinds = frozenset(s.kind for s in sources)
        if len(self.kinds) != len(sources) or Evidence.FACE in self.kinds or Evidence.BOTH in self.kinds:
            raise ValueError(f"evidence sources need distinct kinds other than face / both, got "
                             f"{[s.kind for s in sources]}")

    def __iter__(self) -> Iterator[EvidenceSource]:
        return iter(self.sources)

    def track_identified(self, track_id: int, face_id: int, teaches: bool) -> None:
        """What the track's cues gathered describes face ``face_id``'s person now if its decision ``teaches``, else it
        goes."""
        if not teaches:
            self.forget_track(track_id)
            return
        for source in self.sources:
            source.track_identified(track_id, face_id)

    def forget_track(self, track_id: int) -> None:
        for source in self.sources:
            source.forget_track(track_id)

    def forget_face(self, face_id: int) -> None:
        for source in self.sources:
            source.forget_face(face_id)
