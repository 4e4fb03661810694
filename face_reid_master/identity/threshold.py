"""The threshold baseline of Koide et al. 2017's evaluation: nearest learned face by eq. 4, majority vote."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.identity.algorithm1 import IdentityManagerBase
from face_reid_master.identity.entries import TrackRecord, Vote

__all__ = ["ThresholdIdentityManager"]

F32Array = npt.NDArray[np.float32]


class ThresholdIdentityManager(IdentityManagerBase):
    """The paper's baseline: per observation, nearest learned face if its eq. 4 distance is below
    ``distance_threshold`` else "new"; decide by majority after ``n_votes`` observations.

    Ties: a face beats "new" only with strictly more votes; among faces the smaller mean distance wins.
    The remaining arguments are those of :class:`IdentityManagerBase`.
    """

    def __init__(
        self,
        *,
        distance_threshold: float = 0.6,
        n_votes: int = 5,
        **bank_args: Any,
    ) -> None:
        super().__init__(**bank_args)  # embedding_dim, max_features_per_face, ...: see IdentityManagerBase
        self.distance_threshold = check_real(
            "distance_threshold", distance_threshold, 0.0, math.inf, low_open=True, high_open=True
        )
        self.n_votes = check_int("n_votes", n_votes, 1)

    def _ingest_unassigned(self, track_ids: list[int], observations: list[F32Array],
                           eye_px: list[npt.NDArray[np.float64]]) -> None:
        obs = np.concatenate(observations) if len(observations) > 1 else observations[0]
        d = self.faces.distances(obs)
        if d.shape[1]:
            j = np.argmin(d, axis=1)
            dmin = d[np.arange(d.shape[0]), j]
        else:
            j = np.zeros(obs.shape[0], dtype=np.intp)
            dmin = np.full(obs.shape[0], np.inf)
        pos = 0
        for tid, o in zip(track_ids, observations, strict=True):
            votes = self.tracks.entries[tid].votes
            for r in range(pos, pos + o.shape[0]):
                if dmin[r] < self.distance_threshold:
                    votes.append(Vote(self.faces.available[int(j[r])], float(dmin[r])))
                else:
                    votes.append(Vote(0, float(dmin[r])))
            pos += o.shape[0]

    def _tally(self, track: TrackRecord) -> tuple[int, float]:
        """(winner: face id or 0 = new, vote fraction) over votes for faces still in face_list."""
        available = set(self.faces.available)
        counts: dict[int, list[float]] = {}
        for vote in track.votes:
            if vote.face_id == 0 or vote.face_id in available:
                counts.setdefault(vote.face_id, []).append(vote.distance)
        if not counts:
            return 0, 0.0
        total = sum(len(v) for v in counts.values())
        faces = [(-len(v), float(np.mean(v)), fid) for fid, v in counts.items() if fid != 0]
        n_new = len(counts.get(0, []))
        if faces:
            neg_n, _, fid = min(faces)
            if -neg_n > n_new:
                return fid, -neg_n / total
        return 0, n_new / total

    def _current_confidence(self, track: TrackRecord) -> float:
        _, fraction = self._tally(track)
        return fraction

    def _decide(self) -> list[tuple[int, int, float]]:
        decisions = []
        taken: set[int] = set()
        for track in self.tracks.entries.values():
            if track.face_id is not None or len(track.votes) < self.n_votes:
                continue
            track.votes = [v for v in track.votes if v.face_id not in taken]
            winner, frac = self._tally(track)
            if winner != 0:
                taken.add(winner)
            decisions.append((track.track_id, winner, frac))
        return decisions

    def _make_unavailable(self, face_ids: list[int]) -> None:
        super()._make_unavailable(face_ids)
        gone = set(face_ids)
        for track in self.tracks.entries.values():
            if track.face_id is None and track.votes:
                track.votes = [v for v in track.votes if v.face_id not in gone]

