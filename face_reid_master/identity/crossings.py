"""Crossings carry doubt: two tracks the tracker could have swapped share the probability that it did, until the
evidence on either track decides it.

The tracker reports, per frame, the pairs of tracks its association could have given each other's person, with the
probability ``p`` that it did. For a pair of which at least one track carries an identity, the doubt ``d`` (the
probability that the two tracks' people are exchanged) follows the frames as an odd number of swaps:
``d <- d (1 - p) + (1 - d) p``. A face observation on either track then weighs the two hypotheses with the face
likelihood: observed on track A, it is A's identity's person if they were not swapped and B's if they were (an
unidentified track's identity is "someone not learned", log ratio 0), so
``logit d += log_ratio(B's face) - log_ratio(A's face)``, each observation bounded by ``max_log_ratio``; body
observations weigh it likewise against the faces' recent bodies. Once ``d`` passes the cue's decision threshold
(the face's or the body's posterior threshold) the tracks exchange their identities (and published ids: each
follows its person again) and the doubt becomes ``1 - d``; when the evidence came from an identified track whose
partner has no identity, it shows only whom the track is not: the track lets its face go, undecided. Below
``floor`` the crossing is forgotten. The association alone never makes a swap the likelier story (``p`` is taken
at most one half: it chose the assignment it made); while a track's doubt over all its crossings is above one half,
its identity is more likely wrong than right and is not published.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.entries import Chunk, TrackRecord, rows_of
from face_reid_master.identity.evidence import CueChunk, Cues, EvidenceSource
from face_reid_master.identity.face_list import FaceList
from face_reid_master.identity.records import IdentityEvent, IdentityEventKind, IdentityStats
from face_reid_master.identity.track_list import TrackList

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
    """The doubt of each pair of crossed tracks (kept in both tracks' records, ``TrackRecord.crossed``) and the
    exchanges it leads to, over the identity manager's ``tracks`` and ``faces`` (see the module doc).
    ``drop_buffer(track)``: an unidentified track about to take a face gives up its classification buffer.
    ``face_log_ratios`` / ``face_threshold``: the classification method's face likelihood and posterior threshold
    (None: face observations do not weigh crossings)."""

    def __init__(self, tracks: TrackList, faces: FaceList, sources: Cues, stats: IdentityStats,
                 drop_buffer: Callable[[TrackRecord], None], floor: float = 0.01, max_log_ratio: float = 4.0) -> None:
        self.tracks = tracks
        self.faces = faces
        self.sources = sources
        self.stats = stats
        self.drop_buffer = drop_buffer
        self.floor = floor
        self.max_log_ratio = max_log_ratio
        self.face_log_ratios: FaceLogRatios | None = None
        self.face_threshold = 0.95

    # ------------------------------------------------------------------------------ the tracker's report
    def crossed(self, a: int, b: int, p: float, stamp: float) -> None:
        """The tracker's association may have swapped the people of tracks ``a`` and ``b`` with probability ``p``
        (ignored unless one of them carries an identity)."""
        tracks = self.tracks
        if a == b or tracks.gone(a) or tracks.gone(b):
            return
        ra, rb = tracks.entries.get(a), tracks.entries.get(b)
        if (ra is None or ra.face_id is None) and (rb is None or rb.face_id is None):
            return
        ra, rb = ra or tracks.seen(a, stamp, latest=False), rb or tracks.seen(b, stamp, latest=False)
        p = min(p, 0.5)  # the association chose: it alone never makes the swap the likelier story
        d = ra.crossed.get(b, 0.0)
        self._set(ra, rb, d * (1.0 - p) + (1.0 - d) * p)

    # ------------------------------------------------------------------------------ evidence
    def weigh_faces(self, pending: dict[int, list[Chunk]], stamp: float) -> list[IdentityEvent]:
        """The queued face observations of crossed tracks weigh their crossings (each bounded by
        ``max_log_ratio``); the exchanges they decide (past ``face_threshold``)."""
        events: list[IdentityEvent] = []
        log_ratios = self.face_log_ratios
        for tid, chunks in pending.items() if log_ratios is not None else ():
            track = self.tracks.entries[tid]
            if track.crossed:
                rows = rows_of(chunks)

                def of(faces: list[int], rows: F32Array = rows) -> dict[int, float] | None:
                    lr = log_ratios(rows, faces)
                    if lr is None:
                        return None
                    return dict(zip(faces, np.clip(lr, -self.max_log_ratio, self.max_log_ratio).sum(axis=0).tolist(),
                                    strict=True))
                events += self._weigh(track, of, self.face_threshold, stamp)
        return events

    def weigh_cue(self, source: EvidenceSource, queued: list[tuple[TrackRecord, list[CueChunk]]],
                  stamp: float) -> list[IdentityEvent]:
        """A cue's queued observations of crossed tracks weigh their crossings, when the cue can (it has
        ``face_log_ratios`` and ``posterior_threshold``, as the body); the exchanges they decide."""
        log_ratios = getattr(source, "face_log_ratios", None)
        events: list[IdentityEvent] = []
        for track, parts in queued if log_ratios is not None else ():
            if track.crossed and track.track_id in self.tracks.entries:
                events += self._weigh(track, lambda faces, p=parts: log_ratios(p, faces),
                                      source.posterior_threshold, stamp)  # type: ignore[attr-defined]
        return events

    def _weigh(self, track: TrackRecord, log_ratio_of: LogRatioOf, threshold: float,
               stamp: float) -> list[IdentityEvent]:
        """Observations of a crossed ``track`` weigh each of its crossings (``log_ratio_of(face ids)``: their summed
        log ratio "same person" for each of those faces, None when the cue cannot tell); the exchanges of the pairs
        now swapped with a probability above ``threshold``."""
        events = []
        for pid, d in list(track.crossed.items()):
            other = self.tracks.entries.get(pid)
            if other is None:
                track.crossed.pop(pid, None)
                continue
            column = log_ratio_of([f for f in (track.face_id, other.face_id) if f is not None])
            if column is None:
                return []
            own = column.get(track.face_id, 0.0) if track.face_id is not None else 0.0
            theirs = column.get(other.face_id, 0.0) if other.face_id is not None else 0.0
            d = 1.0 / (1.0 + math.exp(-max(-700.0, min(700.0, _logit(d) + theirs - own))))
            if d > threshold and track.face_id is not None and other.face_id is None:
                track.crossed.pop(pid, None)  # its evidence says only whom it is not: it lets its face go
                other.crossed.pop(track.track_id, None)
                events.append(self.release(track, stamp))
            elif d > threshold:
                self._set(track, other, 1.0 - d)
                events.append(self.exchange(Exchange(track, other, d), stamp))
            else:
                self._set(track, other, d)
        return events

    def exchange(self, ex: Exchange, stamp: float) -> IdentityEvent:
        """Two crossed tracks were swapped: each takes the other's identity (an unidentified one's buffer goes:
        it was gathered on both people)."""
        a, b = ex.first, ex.second
        given = [(b, a.face_id, a.confidence, a.evidence, a.new_face), (a, b.face_id, b.confidence, b.evidence,
                                                                         b.new_face)]
        for track, fid, confidence, evidence, new in given:
            track.inconsistent.clear()
            if fid is None:
                track.unassign()
                continue
            if track.face_id is None:
                self.drop_buffer(track)
            track.give(fid, confidence, evidence, new)
            track.face_confirmed_s = -math.inf
            self.faces.entries[fid].track_id = track.track_id
            self.sources.track_identified(track.track_id, fid)
        self.stats.crossings_exchanged += 1
        return IdentityEvent(IdentityEventKind.EXCHANGED, a.track_id, a.face_id or 0, stamp, ex.probability,
                             partner=b.track_id)

    def release(self, track: TrackRecord, stamp: float) -> IdentityEvent:
        """A crossed track's evidence shows it is not its face's person, and its partner had no identity to give:
        the face returns to face_list, the track goes on undecided (as a swap the swap guard found)."""
        assert track.face_id is not None
        fid, confidence = track.face_id, track.confidence
        self.faces.make_available(fid)
        track.unassign()
        track.inconsistent.clear()
        self.stats.swaps_released += 1
        return IdentityEvent(IdentityEventKind.SWAPPED, track.track_id, fid, stamp, confidence, stamp)

    # ------------------------------------------------------------------------------ queries and ends
    @staticmethod
    def doubt(track: TrackRecord) -> float:
        """The probability that the track's person is not the one its identity was decided on (any crossing)."""
        keep = 1.0
        for d in track.crossed.values():
            keep *= 1.0 - d
        return 1.0 - keep

    def forget_all(self, track: TrackRecord) -> None:
        """The track is gone or identified afresh: its crossings are over (in its partners' records too)."""
        for pid in list(track.crossed):
            track.crossed.pop(pid, None)
            other = self.tracks.entries.get(pid)
            if other is not None:
                other.crossed.pop(track.track_id, None)

    def _set(self, a: TrackRecord, b: TrackRecord, d: float) -> None:
        if d < self.floor:
            a.crossed.pop(b.track_id, None)
            b.crossed.pop(a.track_id, None)
        else:
            a.crossed[b.track_id] = b.crossed[a.track_id] = d
