"""Crossings carry doubt: two tracks the tracker could have swapped share the probability that it did, and a track
whose identity has become more likely wrong than right is not published with it.

The tracker reports, per frame, the pairs of tracks its association could have given each other's person, with the
probability ``p`` that it did (taken at most one half: the association chose the assignment it made). For a pair of
which at least one track carries an identity, the doubt ``d`` (the probability that the two tracks' people are
exchanged) follows the frames as an odd number of swaps: ``d <- d (1 - p) + (1 - d) p``. The tracker also
reports the probability ``p`` that the detection a track took is a person it was not following (one whose own
track is new or gone, as when its person leaves the view while another walks in); for an identified track this
is a crossing with nobody, not bounded by one half: ``d <- 1 - (1 - d) (1 - p)``. A track's
``identity_confidence`` falls with its doubt over all its crossings, and above one half its identity is withheld:
the identity manager releases it at its next step, as a swapped track (under a new published id). Its face returns
to face_list at once, so the person's own track can take it when it shows the face (held by the swapped track, it
would have given them a new id), and the released track is decided afresh by its next face or body. An unidentified
track's strays add up alike; above one half its face buffer and body evidence are another person's more likely
than not: the identity manager drops them and classifies the track afresh from its next observations (it keeps its
published id: it claimed nobody). A decision of the track clears its doubt, and its partners' about it; the
partner's end does not (it says nothing of a swap before it). Below ``floor`` a crossing is forgotten. Past one
half of doubt a track more likely follows another person: what it was seen alongside is forgotten
(:mod:`~.co_sightings`).

Measured on the development scenarios and dropped: clearing the doubt when the partner ends (of the identities it
gave back, 42 % were wrong with oracle evidence and 57 % with real evidence), or when the swap guard's gate accepts
a face seen on the track again (with real evidence almost every identity it gave back was wrong: the gate takes a
look-alike's face for the person's; deciding afresh, by the classification, won); weighing it by the faces and
bodies seen next, and exchanging the identities of two tracks it showed swapped (oracle evidence, 20 people);
weighing it, strays included, by the bodies an identified track shows next, its bodies held from its face meanwhile
(oracle evidence gained little; with real evidence, 20 people, wrong identity per detection rose 3.7 -> 4.7 %: the
bodies of whoever the track took often looked like its face's, and lowered the doubt); the same counted only against
the track's own face, with its bodies held from its face until the doubt is gone, is not adopted: the development
scenarios are split on it. It won on two 20-person seeds (oracle 4 -> 3 and 6 -> 4 wrong decisions, real 65 -> 58
and 60 -> 55; at 1920x1080 23 -> 19) and on 6 people over 5 seeds (oracle 3 -> 0); it lost on a third 20-person
seed (oracle 12 -> 13 wrong and wrong identity per detection 0.9 -> 1.1 %, real 53 -> 56 and 1.0 -> 1.1 %: the
tracks it decided earlier by body were right when decided, then a tracker switch their bodies did not reveal
carried two of them onto another person) and was even on a seed whose people include the two closest faces of
the development set (oracle 5 -> 5 wrong, 399 -> 389 right); on the held-out 20 people it lost (oracle 9 -> 13
and 0.7 -> 1.4 %, real 59 -> 68 and 1.6 -> 2.0 %); publishing an unidentified track classified afresh under a
new id (what a robot reads was the same, but the tracks were cut into many short undecided ones).
"""

from __future__ import annotations

from face_reid_camera.common.checks import check_real, check_stamp
from face_reid_master.identity.entries import TrackRecord
from face_reid_master.identity.track_list import TrackList

__all__ = ["NOBODY", "Crossings"]

NOBODY = -1  # the partner of a stray in TrackRecord.crossed (no track has a negative id)


class Crossings:
    """The doubt of each pair of crossed tracks of the identity manager's ``tracks`` (kept in both tracks' records,
    ``TrackRecord.crossed``; see the module doc)."""

    def __init__(self, tracks: TrackList, floor: float = 0.01) -> None:
        self.tracks = tracks
        self.floor = floor

    # ------------------------------------------------------------------------------ the tracker's report
    def crossed(self, a: int, b: int, p: float, stamp: float) -> None:
        """The tracker's association may have swapped the people of tracks ``a`` and ``b`` with probability ``p``
        (ignored unless one of them carries an identity)."""
        p = check_real("probability", p, 0.0, 1.0)
        stamp = check_stamp(stamp)
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

    def strayed(self, a: int, p: float) -> None:
        """The detection track ``a`` took may be a person it was not following, with probability ``p`` (ignored
        for a track the identity manager holds nothing of)."""
        p = check_real("probability", p, 0.0, 1.0)
        track = self.tracks.entries.get(a)
        if track is None:
            return
        d = 1.0 - (1.0 - track.crossed.get(NOBODY, 0.0)) * (1.0 - p)
        if d >= self.floor:
            track.crossed[NOBODY] = d
            self._person_may_have_changed(track)

    # ------------------------------------------------------------------------------ queries and ends
    def doubt_of(self, track_id: int) -> float:
        """The probability that a live track's person is not the one its identity was decided on (0 when unknown)."""
        track = self.tracks.entries.get(track_id)
        return 0.0 if track is None else self.doubt(track)

    def withholds(self, track_id: int) -> bool:
        """Whether the track's identity is more likely wrong than right: published as undecided."""
        return self.withheld_at(self.doubt_of(track_id))

    def withheld(self) -> list[TrackRecord]:
        """The identified live tracks whose identity is more likely wrong than right."""
        return [t for t in self.tracks.entries.values()
                if t.face_id is not None and t.crossed and self.withheld_at(self.doubt(t))]

    def take_mixed(self) -> list[TrackRecord]:
        """The unidentified live tracks whose evidence so far is more likely another person's than their current
        person's (a stray more likely than not), to be classified afresh: their strays are spent."""
        mixed = [t for t in self.tracks.entries.values()
                 if t.face_id is None and self.withheld_at(t.crossed.get(NOBODY, 0.0))]
        for track in mixed:
            self.forget_strays(track)
        return mixed

    @staticmethod
    def withheld_at(doubt: float) -> bool:
        """Whether an identity with this doubt is withheld (more likely wrong than right)."""
        return doubt > 0.5

    @staticmethod
    def doubt(track: TrackRecord) -> float:
        """The probability that the track's person is not the one its identity was decided on (any crossing)."""
        keep = 1.0
        for d in track.crossed.values():
            keep *= 1.0 - d
        return 1.0 - keep

    @staticmethod
    def forget_strays(track: TrackRecord) -> None:
        """The track's strays so far are spent (it was released or classified afresh for them)."""
        track.crossed.pop(NOBODY, None)

    def forget_all(self, track: TrackRecord) -> None:
        """The track is identified afresh: its crossings are over (in its partners' records too)."""
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
            self._person_may_have_changed(a)
            self._person_may_have_changed(b)

    def _person_may_have_changed(self, track: TrackRecord) -> None:
        """Past one half of doubt the track more likely follows another person (:mod:`~.co_sightings`)."""
        if self.withheld_at(self.doubt(track)):
            track.person_changed()
