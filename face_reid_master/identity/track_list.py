"""track_list of Algorithm 1: the live tracks, one :class:`~face_reid_master.identity.entries.TrackRecord` each.

A track's record holds everything the master keeps about it (its queued face and body observations, its
decision, its Bayes row, its published id); :meth:`TrackList.remove` drops it whole once the tracker dropped
the track and its death was handled (at the identity step, after its last evidence). The ids of deleted tracks
are remembered (the newest ``MEMORY`` of them): a late observation of a deleted track is ignored, never taken
for a new track.
"""

from __future__ import annotations

from collections import OrderedDict

from face_reid_master.identity.entries import Chunk, TrackRecord
from face_reid_master.identity.evidence import CueChunk

__all__ = ["TrackList"]


class TrackList:
    """The live tracks' records (:attr:`entries`), which of them have work queued for the next step, and the
    deaths (:attr:`deaths`); see the module doc."""

    MEMORY = 4096  # ids of deleted tracks remembered to ignore late observations

    def __init__(self) -> None:
        self.entries: dict[int, TrackRecord] = {}
        self.deaths: dict[int, float] = {}  # track id -> stamp the tracker dropped it
        self.retired: dict[int, TrackRecord] = {}  # removed at the last step (read for their events, then cleared)
        self._face_queued: dict[int, TrackRecord] = {}  # in queueing order: the step learns them in that order
        self._cue_queued: dict[str, dict[int, TrackRecord]] = {}  # per cue kind, likewise
        self._dead: OrderedDict[int, float] = OrderedDict()

    def gone(self, track_id: int) -> bool:
        """Whether the track was deleted (or is about to be): its evidence is ignored."""
        return track_id in self._dead or track_id in self.deaths

    def record(self, track_id: int) -> TrackRecord | None:
        """The track's record: a live one, or one removed at the last step (its events are still being read)."""
        rec = self.entries.get(track_id)
        return self.retired.get(track_id) if rec is None else rec

    def seen(self, track_id: int, stamp: float, latest: bool = True) -> TrackRecord:
        """The track was seen at ``stamp``: a new record, or (``latest``) its last sighting moves on."""
        track = self.entries.get(track_id)
        if track is None:
            track = self.entries[track_id] = TrackRecord(track_id, first_seen_s=stamp, last_seen_s=stamp,
                                                         person_since_s=stamp)
        elif latest:
            track.last_seen_s = max(track.last_seen_s, stamp)
        return track

    def queue(self, track_id: int, chunk: Chunk) -> None:
        """Face observations of the track for the next step."""
        track = self.seen(track_id, chunk.stamp_s)
        track.face_chunks.append(chunk)
        self._face_queued.setdefault(track_id, track)

    def queue_cue(self, kind: str, track_id: int, chunk: CueChunk) -> None:
        """Observations of cue ``kind`` (not the face) on the track for the next step."""
        track = self.seen(track_id, chunk.stamp_s)
        track.cue_queue.setdefault(kind, []).append(chunk)
        self._cue_queued.setdefault(kind, {}).setdefault(track_id, track)

    def drop_faces(self, track: TrackRecord) -> None:
        """The track's queued face observations go (they were meant for a face that was forgotten)."""
        track.face_chunks = []
        self._face_queued.pop(track.track_id, None)

    def died(self, track_id: int, stamp: float) -> None:
        if track_id not in self._dead:
            self.deaths[track_id] = stamp

    def take_pending(self) -> dict[int, list[Chunk]]:
        """The queued face observations per track, in queueing order; the queues are emptied."""
        queued, self._face_queued = self._face_queued, {}
        pending = {}
        for tid, track in queued.items():
            pending[tid], track.face_chunks = track.face_chunks, []
        return pending

    def take_cue(self, kind: str, learn_confidence: float) -> tuple[list[tuple[TrackRecord, list[CueChunk]]], int]:
        """The queued observations of cue ``kind`` per track, in queueing order, of the faceless tracks and
        the identified ones that teach (:meth:`TrackRecord.teaches`: not those a face decided below
        ``learn_confidence``), and how many rows the others held. Those queues are emptied."""
        queued = self._cue_queued.pop(kind, {})
        taught, withheld = [], 0
        for track in queued.values():
            chunks = track.cue_queue.pop(kind)
            # faceless first: a track whose lent face was forgotten keeps its decision's evidence kind, not a face
            if track.face_id is None or track.teaches(learn_confidence):
                taught.append((track, chunks))
            else:
                withheld += sum(c.values.shape[0] for c in chunks)
        return taught, withheld

    def remove(self, track_id: int, stamp: float) -> TrackRecord | None:
        """The track is gone for good (its death handled): its record goes with everything in it (kept in
        :attr:`retired` until the caller clears it); the record, if it had one."""
        self._dead[track_id] = stamp
        while len(self._dead) > self.MEMORY:
            self._dead.popitem(last=False)
        self._face_queued.pop(track_id, None)
        for queued in self._cue_queued.values():
            queued.pop(track_id, None)
        track = self.entries.pop(track_id, None)
        if track is not None:
            self.retired[track_id] = track
        return track
