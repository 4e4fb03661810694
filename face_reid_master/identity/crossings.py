"""Crossings carry doubt: two tracks the tracker could have swapped share the probability that it did, until the
evidence on either track decides it.

The tracker reports, per frame, the pairs of tracks its association could have given each other's person, with
the probability ``p`` that it did. For a pair of which at least one track carries an identity, the doubt ``d``
(the probability that the two tracks' people are exchanged) follows the frames as an odd number of swaps:
``d <- d (1 - p) + (1 - d) p``. A face observation on either track then weighs the two hypotheses with the face
likelihood: observed on track A, it is A's identity's person if they were not swapped and B's if they were
(an unidentified track's identity is "someone not learned", log ratio 0), so
``logit d += log_ratio(B's face) - log_ratio(A's face)``, each observation bounded by ``max_log_ratio``; body
observations weigh it likewise against the faces' recent bodies. Once ``d`` passes the cue's decision threshold
(the face's or the body's posterior threshold) the tracks exchange their identities (and published ids: each
follows its person again) and the doubt becomes ``1 - d``; once it falls below ``floor`` the crossing is
forgotten. The association alone never makes a swap the likelier story (``p`` is taken at most one half: it chose
the assignment it made); while ``d`` is above one half, a track's identity is more likely wrong than right and
is not published.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.entries import TrackRecord

__all__ = ["Crossings", "Exchange"]

F32Array = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]
# log likelihood ratios (same person vs another) of face observations (Q, dim) for learned faces (their ids):
# (Q, len(faces)), or None when the classification method has no face likelihood
FaceLogRatios = Callable[[F32Array, list[int]], FloatArray | None]
# some observations' summed log likelihood ratio for each of the given faces (None: the cue cannot tell)
LogRatioOf = Callable[[list[int]], dict[int, float] | None]


@dataclass(frozen=True, slots=True)
class Exchange:
    """Two tracks whose people were swapped (``probability``): they exchange their identities."""

    first: TrackRecord
    second: TrackRecord
    probability: float


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


class Crossings:
    """The doubt of each pair of crossed tracks (kept in both tracks' records, ``TrackRecord.crossed``); see the
    module doc."""

    def __init__(self, floor: float = 0.01, max_log_ratio: float = 4.0) -> None:
        self.floor = floor
        self.max_log_ratio = max_log_ratio

    def crossed(self, a: TrackRecord, b: TrackRecord, p: float) -> None:
        """The tracker's association may have swapped the people of ``a`` and ``b`` with probability ``p``."""
        if a is b or (a.face_id is None and b.face_id is None):
            return
        p = min(p, 0.5)  # the association chose: it alone never makes the swap the likelier story
        d = a.crossed.get(b.track_id, 0.0)
        self._set(a, b, d * (1.0 - p) + (1.0 - d) * p)

    @staticmethod
    def withheld(track: TrackRecord) -> bool:
        """Whether a crossing makes the track's identity more likely wrong than right (it is not published)."""
        return any(d > 0.5 for d in track.crossed.values())

    def doubt(self, track: TrackRecord) -> float:
        """The probability that the track's person is not the one its identity was decided on (any crossing)."""
        keep = 1.0
        for d in track.crossed.values():
            keep *= 1.0 - d
        return 1.0 - keep

    def weigh(self, track: TrackRecord, partners: dict[int, TrackRecord], log_ratio_of: LogRatioOf,
              threshold: float) -> list[Exchange]:
        """Observations of a crossed ``track`` weigh each of its crossings (``partners``: the live records by id;
        ``log_ratio_of(face ids)``: the observations' summed log ratio "same person" for each of those faces, None
        when the cue cannot tell); the pairs now swapped with a probability above the cue's ``threshold``."""
        out = []
        for pid, d in list(track.crossed.items()):
            other = partners.get(pid)
            if other is None:
                self.forget(track, pid)
                continue
            column = log_ratio_of([f for f in (track.face_id, other.face_id) if f is not None])
            if column is None:
                return []
            own = column.get(track.face_id, 0.0) if track.face_id is not None else 0.0
            theirs = column.get(other.face_id, 0.0) if other.face_id is not None else 0.0
            d = 1.0 / (1.0 + math.exp(-max(-700.0, min(700.0, _logit(d) + theirs - own))))
            if d > threshold:
                self._set(track, other, 1.0 - d)
                out.append(Exchange(track, other, d))
            else:
                self._set(track, other, d)
        return out

    def face_log_ratios(self, rows: F32Array, log_ratios: FaceLogRatios) -> LogRatioOf:
        """``log_ratio_of`` for face observations ``rows``: each observation's evidence bounded by
        ``max_log_ratio``."""
        def of(faces: list[int]) -> dict[int, float] | None:
            lr = log_ratios(rows, faces)
            if lr is None:
                return None
            np.clip(lr, -self.max_log_ratio, self.max_log_ratio, out=lr)
            return dict(zip(faces, lr.sum(axis=0).tolist(), strict=True))
        return of

    def forget(self, track: TrackRecord, partner: int, records: dict[int, TrackRecord] | None = None) -> None:
        """The crossing of ``track`` with ``partner`` is over (both records, when ``records`` has the partner)."""
        track.crossed.pop(partner, None)
        other = None if records is None else records.get(partner)
        if other is not None:
            other.crossed.pop(track.track_id, None)

    def forget_all(self, track: TrackRecord, records: dict[int, TrackRecord]) -> None:
        """The track is gone or identified afresh: its crossings are over (in its partners' records too)."""
        for pid in list(track.crossed):
            self.forget(track, pid, records)

    def _set(self, a: TrackRecord, b: TrackRecord, d: float) -> None:
        if d < self.floor:
            a.crossed.pop(b.track_id, None)
            b.crossed.pop(a.track_id, None)
        else:
            a.crossed[b.track_id] = b.crossed[a.track_id] = d

    @staticmethod
    def partners(tracks: Iterable[TrackRecord]) -> set[int]:
        """The ids of the tracks crossed with any of ``tracks``."""
        return {pid for t in tracks for pid in t.crossed}
