"""A third cue through the evidence interface alone: a toy badge reader (a constant badge id per person, the
message field a subclass of PersonRecord adds) handed to MasterCore decides who a faceless track is."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.identity.evidence import CueChunk, EvidenceSource, TrackView
from face_reid_master.identity.records import IdentityEventKind
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.tracking.config import TrackerConfig

SPACE = "dlib_resnet_v1"
DIM = 128
BADGE = "badge"  # the cue's kind: what a track it identifies is published as identified by


@dataclass(frozen=True)
class BadgedPerson(PersonRecord):
    """A person with the new message field: the badge id a reader saw on them (0 = none)."""

    badge: int = 0


class BadgeEvidence:
    """The toy cue: a track that showed ``min_observations`` times a badge worn by a learned face's person (seen on
    a track that face identified) is that person."""

    kind = BADGE

    def __init__(self, min_observations: int = 3) -> None:
        self.min_observations = min_observations
        self._wearer: dict[int, int] = {}  # badge -> face id of its person
        self._seen: dict[int, Counter[int]] = {}  # faceless track -> badges seen on it

    def read(self, person: Any, detection: int, detections: Any) -> np.ndarray | None:
        badge = getattr(person, "badge", 0)
        return np.array([[badge]], np.float32) if badge else None

    def observe(self, queued: Sequence[tuple[TrackView, list[CueChunk]]], face_ids: list[int]) -> None:
        for track, chunks in queued:
            for chunk in chunks:
                for badge in chunk.values[:, 0].astype(int).tolist():
                    if track.face_id is not None:
                        self._wearer[badge] = track.face_id
                    elif track.slot is None:  # faceless
                        self._seen.setdefault(track.track_id, Counter())[badge] += 1

    def decide(self, available: list[int], stamp: float, alike: Callable[[int, list[int]], list[bool]]
               ) -> list[tuple[int, int, float]]:
        out, given = [], set()
        for tid, badges in self._seen.items():
            badge, n = badges.most_common(1)[0]
            face = self._wearer.get(badge)
            if face in available and face not in given and n >= self.min_observations:
                given.add(face)
                out.append((tid, face, 1.0))
        return out

    def track_identified(self, track_id: int, face_id: int) -> None:
        for badge in self._seen.pop(track_id, Counter()):
            self._wearer[badge] = face_id

    def forget_track(self, track_id: int) -> None:
        self._seen.pop(track_id, None)

    def forget_face(self, face_id: int) -> None:
        self._wearer = {b: f for b, f in self._wearer.items() if f != face_id}


def _look(k: int, rng: np.random.Generator) -> np.ndarray:
    """One embedding of person k at dlib's length (the master checks it)."""
    v = np.random.default_rng(100 + k).normal(size=DIM) + rng.normal(0.0, 0.02, DIM)
    return (v * 1.4 / np.linalg.norm(v)).astype(np.float32)


def _visit(core: MasterCore, people: dict[int, tuple[int, bool]], t0: float, seconds: float = 2.0) -> tuple[
        float, list[Any]]:
    """People k -> (badge, face shown) walk in view side by side at 10 Hz, then leave until their tracks are
    deleted; the end time and the identity events."""
    rng = np.random.default_rng(int(t0))
    events: list[Any] = []
    n = int(seconds * 10)
    for i in range(n):
        crowd = tuple(BadgedPerson(np.array([0.1 * i, 3.0 * k, 0.0]), 0.05, 1.75,
                                   _look(k, rng) if face else None, 0.9 if face else 0.0, 0.8 if face else 0.0,
                                   badge=badge)
                      for k, (badge, face) in people.items())
        events += core.process_frame(CameraFrameRecord("cam", t0 + i / 10, crowd)).identity_events
    t = t0 + n / 10 + 2.0
    core.tick(t)
    assert core.tracks() == []
    return t, events


def _core(*sources: EvidenceSource) -> MasterCore:
    return MasterCore(MasterConfig(embedding_space=SPACE, body_appearance_tracking=False,
                                   tracker=TrackerConfig(lost_after_s=0.5, delete_after_s=1.0)),
                      evidence_sources=sources)


def test_a_badge_cue_added_through_the_evidence_interface_decides_faceless_tracks() -> None:
    results = {}
    for with_badges in (False, True):
        core = _core(BadgeEvidence()) if with_badges else _core()
        t, first = _visit(core, {0: (7, True), 1: (9, True)}, 0.0)  # both show their faces and badges
        faces = {e.face_id for e in first if e.kind == IdentityEventKind.NEW_FACE}
        assert len(faces) == 2
        _, back = _visit(core, {1: (9, False), 0: (7, False)}, t)  # they come back showing only their badges
        results[with_badges] = [(e.kind, e.face_id, e.evidence) for e in back
                                if e.kind == IdentityEventKind.ASSIGNED_KNOWN]
        first_face = {e.track_id: e.face_id for e in first if e.kind == IdentityEventKind.NEW_FACE}
        if with_badges:  # the badge of each person gave their new track their own face
            owner = dict(zip(sorted(first_face), (0, 1), strict=True))  # person 0's track was made first
            face_of = {owner[tid]: fid for tid, fid in first_face.items()}
            assert sorted(results[True]) == sorted([(IdentityEventKind.ASSIGNED_KNOWN, face_of[0], BADGE),
                                                    (IdentityEventKind.ASSIGNED_KNOWN, face_of[1], BADGE)])
    assert results[False] == []  # without the cue nobody is recognised (no face, no body)
