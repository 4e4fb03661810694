"""Our extension of Algorithm 1: the face of a track the tracker lost is lent back to face_list.

The paper holds a face until its track is deleted, so a person who comes back as a new track meanwhile gets
a new id or nothing. Here, while the tracker has lost a track (LOST), its face is in face_list again, lent:
the person's new track can take it (by face or body); the LOST track takes it back when found again, unless
another track took it.
"""

from __future__ import annotations

from collections.abc import Mapping

from face_reid_master.identity.entries import TrackRecord
from face_reid_master.identity.face_list import FaceList

__all__ = ["LentFaces"]


class LentFaces:
    """The faces lent by LOST tracks (:attr:`lender`: face id -> the LOST track); ``enabled`` False = the paper."""

    def __init__(self, faces: FaceList, enabled: bool) -> None:
        self.faces = faces
        self.enabled = enabled
        self.lender: dict[int, int] = {}

    def lend(self, track: TrackRecord | None) -> None:
        """The tracker lost ``track``: its face goes back to face_list, lent."""
        fid = None if track is None else track.face_id
        if not self.enabled or track is None or fid is None or fid in self.lender or fid in self.faces.available:
            return
        self.faces.make_available(fid)
        self.lender[fid] = track.track_id

    def give_back(self, track: TrackRecord | None) -> None:
        """The LOST ``track`` was detected again: it takes its face back if nobody took it."""
        fid = None if track is None else track.face_id
        if track is not None and fid is not None and self.lender.get(fid) == track.track_id:
            del self.lender[fid]
            self.faces.make_unavailable([fid])
            self.faces.entries[fid].track_id = track.track_id

    def take(self, face_id: int) -> int | None:
        """The face goes to another track (or is forgotten): the LOST track that lent it, if one did."""
        return self.lender.pop(face_id, None)

    def take_holder(self, face_id: int, tracks: Mapping[int, TrackRecord]) -> TrackRecord | None:
        """:meth:`take`, as the record of the LOST track that lent the face while it still holds it (else None)."""
        lender = self.take(face_id)
        track = None if lender is None else tracks.get(lender)
        return track if track is not None and track.face_id == face_id else None

    def returned(self, face_id: int, track_id: int) -> bool:
        """Whether the dying track had lent its face (then it is in face_list already, and no longer lent)."""
        if self.lender.get(face_id) != track_id:
            return False
        del self.lender[face_id]
        return True
