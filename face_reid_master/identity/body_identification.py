"""Our extension of Algorithm 1: a track that shows no face is identified by its body.

Body observations are queued per track until the identity step; then those of identified tracks join their
face's body gallery and those of faceless tracks are weighed against every learned face's recent bodies
(:class:`~face_reid_master.identity.body_evidence.BodyEvidence`), which decides the faceless tracks whose
evidence is strong enough. A track's own face, once seen, overrules its body.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.entries import TrackEntry

__all__ = ["BodyIdentification"]

F32Array = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]


class BodyIdentification:
    """The body observations waiting for the identity step and the evidence they feed (see the module doc)."""

    def __init__(self, evidence: BodyEvidence) -> None:
        if not isinstance(evidence, BodyEvidence):
            raise ValueError(f"body_evidence must be a BodyEvidence or None, got {type(evidence).__name__}")
        self.evidence = evidence
        self._pending: dict[int, list[tuple[F32Array, float, str, FloatArray | None]]] = {}

    def queue(self, track_id: int, embeddings: F32Array, stamp_s: float, source: str,
              heights: FloatArray | None) -> None:
        self._pending.setdefault(track_id, []).append((embeddings, stamp_s, source, heights))

    def forget_track(self, track_id: int) -> None:
        """The track was deleted: its queued bodies and its evidence go."""
        self._pending.pop(track_id, None)
        self.evidence.forget_track(track_id)

    def observe(self, tracks: dict[int, TrackEntry], face_ids: list[int]) -> None:
        """The queued bodies: an identified track's join its face's gallery; a faceless track's (one not
        buffering face observations) are compared with the recent bodies of every face in ``face_ids``."""
        pending, self._pending = self._pending, {}
        for tid, parts in pending.items():
            track = tracks.get(tid)
            if track is None:
                continue
            for emb, t, source, heights in parts:
                if track.face_id is not None:
                    self.evidence.add_face_bodies(track.face_id, emb, t, heights)
                else:  # faceless tracks are compared; the others only keep their bodies for their face
                    self.evidence.observe(tid, emb, t, face_ids if track.slot is None else [], source, heights)

    def decide(self, available: list[int], stamp: float,
               alike: Callable[[int, list[int]], list[bool]]) -> list[tuple[int, int, float]]:
        """(track id, face id, posterior) of the faceless tracks their bodies decide now (faces of face_list)."""
        return self.evidence.decide(available, stamp, alike)

    def move_track_bodies(self, track_id: int, face_id: int) -> None:
        """The bodies a track gathered before its decision join its face's gallery."""
        emb, newest, heights = self.evidence.track_bodies(track_id)
        if emb.shape[0]:
            self.evidence.add_face_bodies(face_id, emb, newest, heights=heights)
        self.evidence.forget_track(track_id)
