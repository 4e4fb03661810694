"""A face held by another live track is no reason for a new id.

When the classification calls an unassigned track a new person, its buffered features may be those of a learned
face that another live track carries (such a face is not in face_list, so the classification had nothing to
compare them with). Then either the two tracks are one person twice (a duplicate: the holder showed that face
since the new track's buffer began) and the new track stays undecided, or the holder was swapped onto someone
else and carries the face wrongly (it has not shown the face since): it gives the face up, and the new track
takes it. A new id there would split one person over two faces, and the posterior of their next return would
split between them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.entries import TrackRecord
from face_reid_master.identity.face_list import FaceList
from face_reid_master.identity.records import IdentityStats

__all__ = ["HeldFace", "HeldFaces"]

F32Array = npt.NDArray[np.float32]


@dataclass(frozen=True, slots=True)
class HeldFace:
    """The held face an unassigned track's buffer shows, its holder, and whether the two are one person twice."""

    face_id: int
    holder: TrackRecord
    duplicate: bool  # one person twice, or unsure whether it is that face's person: the track waits

    @property
    def since_s(self) -> float:
        """Since when the holder may have carried someone else (its last sight of the face, or its start)."""
        return max(self.holder.face_confirmed_s, self.holder.first_seen_s)


class HeldFaces:
    """Finds the held face a "new person" decision would duplicate: the one a majority of the buffered features lie
    within ``gate_distance`` of (None = off, the paper), weighed by ``face_log_ratios`` (the classification method's
    face likelihood: the buffer is that face's person past ``face_threshold``, someone else below one minus it,
    unsure between: the track waits; None: the majority decides)."""

    def __init__(self, gate_distance: float | None, faces: FaceList, stats: IdentityStats) -> None:
        self.gate_distance = gate_distance
        self.faces = faces
        self.stats = stats
        self.face_log_ratios: Callable[[F32Array, list[int]], npt.NDArray[np.float64]] | None = None
        self.face_threshold = 0.95
        self.max_log_ratio = 4.0  # one feature's evidence, as a crossing's
        # metres between two live tracks now (inf: unknown); the master core gives the tracker's
        self.apart: Callable[[int, int], float] = lambda a, b: math.inf
        self.duplicate_within_m = 1.0

    def shown_by(self, track: TrackRecord, tracks: dict[int, TrackRecord]) -> HeldFace | None:
        """The face held by another live track that most of ``track``'s buffered features lie within the gate of
        (None: none, or the gate is off)."""
        gate = self.gate_distance
        if gate is None or track.slot is None:
            return None
        held = [f for f in self.faces.entries.values()
                if f.track_id is not None and f.track_id != track.track_id and f.track_id in tracks]
        if not held:
            return None
        bank = self.faces.bank
        obs = bank.features(track.slot)
        close = np.count_nonzero(bank.exact_min_distances(obs, np.array([f.slot for f in held], np.intp)) < gate,
                                 axis=0)
        best = int(np.argmax(close))
        if 2 * int(close[best]) <= obs.shape[0]:
            return None
        face = held[best]
        holder = tracks[face.track_id]  # type: ignore[index]
        sure = True
        if self.face_log_ratios is not None:
            cap = self.max_log_ratio
            lr = float(np.clip(self.face_log_ratios(obs, [face.face_id]), -cap, cap).sum())
            p = 1.0 / (1.0 + math.exp(-max(-700.0, min(700.0, lr))))
            if p < 1.0 - self.face_threshold:
                return None  # a look-alike: the new person is new
            sure = p > self.face_threshold
        duplicate = (not sure or holder.face_confirmed_s >= track.buffer_since_s
                     or self.apart(holder.track_id, track.track_id) < self.duplicate_within_m)
        if duplicate:
            self.stats.new_ids_held_waiting += 1
        else:
            self.stats.held_faces_taken += 1
        return HeldFace(face.face_id, holder, duplicate)
