"""track_list of Algorithm 1: the live tracks as the identity layer sees them.

With each track, the face observations queued for the next identity step and, once the tracker drops it, its
death (handled at that step, after its last evidence). The ids of deleted tracks are remembered (the newest
``MEMORY`` of them): a late observation of a deleted track is ignored, never taken for a new track.
"""

from __future__ import annotations

from collections import OrderedDict

from face_reid_master.identity.entries import Chunk, TrackEntry

__all__ = ["TrackList"]


class TrackList:
    """The live tracks (:attr:`entries`), their queued observations (:attr:`pending`) and deaths
    (:attr:`deaths`); see the module doc."""

    MEMORY = 4096  # ids of deleted tracks remembered to ignore late observations

    def __init__(self) -> None:
        self.entries: dict[int, TrackEntry] = {}
        self.pending: dict[int, list[Chunk]] = {}
        self.deaths: dict[int, float] = {}  # track id -> stamp the tracker dropped it
        self._dead: OrderedDict[int, float] = OrderedDict()

    def gone(self, track_id: int) -> bool:
        """Whether the track was deleted (or is about to be): its evidence is ignored."""
        return track_id in self._dead or track_id in self.deaths

    def seen(self, track_id: int, stamp: float, latest: bool = True) -> None:
        """The track was seen at ``stamp``: a new entry, or (``latest``) its last sighting moves on."""
        track = self.entries.get(track_id)
        if track is None:
            self.entries[track_id] = TrackEntry(track_id, first_seen_s=stamp, last_seen_s=stamp)
        elif latest:
            track.last_seen_s = max(track.last_seen_s, stamp)

    def queue(self, track_id: int, chunk: Chunk) -> None:
        """Face observations of the track for the next step."""
        self.pending.setdefault(track_id, []).append(chunk)
        self.seen(track_id, chunk.stamp_s)

    def died(self, track_id: int, stamp: float) -> None:
        if track_id not in self._dead:
            self.deaths[track_id] = stamp

    def take_pending(self) -> dict[int, list[Chunk]]:
        pending, self.pending = self.pending, {}
        return pending

    def remove(self, track_id: int, stamp: float) -> TrackEntry | None:
        """The track is gone for good (its death handled); its entry, if it had one."""
        self._dead[track_id] = stamp
        while len(self._dead) > self.MEMORY:
            self._dead.popitem(last=False)
        self.pending.pop(track_id, None)
        return self.entries.pop(track_id, None)
