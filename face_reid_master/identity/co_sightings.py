"""Two tracks seen at the same time are two people: a face carried by a track that was seen alongside an
unidentified one is not the unidentified track's person.

Each track record keeps the span over which it has followed one person (``person_since_s`` to ``last_seen_s``:
from its first sighting, or from the crossing or stray that made another person likelier than not, to its last
sighting). When an identified track whose identity is published (not withheld by a crossing) and an unidentified
one have both been seen over a common span longer than ``overlap_s``, the identified track's face joins the
unidentified one's ``not_faces``: neither its face nor its body may decide it for that face, even after the face's
track is lost or gone (it stays undecided rather). Once a crossing or a stray (:mod:`~.crossings`) makes another
person likelier than not on the track, its span restarts and its ``not_faces`` are cleared. The overlap asked for
keeps a person the tracker handed from one track to the next (the old track's last sighting just before the new
one's first) from being excluded from their own face.
"""

from __future__ import annotations

import math

from face_reid_camera.common.checks import check_real
from face_reid_master.identity.crossings import Crossings
from face_reid_master.identity.records import IdentityStats
from face_reid_master.identity.track_list import TrackList

__all__ = ["CoSightings"]


class CoSightings:
    """The faces each unidentified track of ``tracks`` cannot be (see the module doc)."""

    def __init__(self, tracks: TrackList, stats: IdentityStats, overlap_s: float = 1.0) -> None:
        self.tracks = tracks
        self.stats = stats
        self.overlap_s = check_real("overlap_s", overlap_s, 0.0, math.inf)

    def note(self) -> None:
        """After a step's observations: each unidentified track learns the faces of tracks seen alongside it."""
        records = list(self.tracks.entries.values())
        held = [(t, t.face_id) for t in records
                if t.face_id is not None and not Crossings.withheld_at(Crossings.doubt(t))]
        if not held:
            return
        for track in records:
            if track.face_id is not None:
                continue
            for other, face in held:
                if (face not in track.not_faces and min(track.last_seen_s, other.last_seen_s)
                        - max(track.person_since_s, other.person_since_s) > self.overlap_s):
                    track.not_faces.add(face)

    def allowed(self, decisions: list[tuple[int, int, float]]) -> list[tuple[int, int, float]]:
        """The (track, face or 0 = new, confidence) decisions not excluded (:meth:`excludes`)."""
        return [d for d in decisions if not self.excludes(d[0], d[1])]

    def excludes(self, track_id: int, face_id: int) -> bool:
        """Whether the face's track was seen alongside this live track (so it is not its person): a decision
        for it is not taken (and counted)."""
        track = self.tracks.entries.get(track_id)
        if track is None or face_id not in track.not_faces:
            return False
        self.stats.decisions_excluded_co_seen += 1
        return True
