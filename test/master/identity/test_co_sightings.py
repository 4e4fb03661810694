"""Two tracks seen at the same time are two people (identity/co_sightings.py)."""

from __future__ import annotations

from face_reid_master.identity.co_sightings import CoSightings
from face_reid_master.identity.crossings import Crossings
from face_reid_master.identity.records import IdentityStats
from face_reid_master.identity.track_list import TrackList


def _seen(tracks: TrackList, track_id: int, *stamps: float, face: int | None = None) -> None:
    for t in stamps:
        tracks.seen(track_id, t)
    if face is not None:
        tracks.entries[track_id].face_id = face


def test_a_track_seen_alongside_a_face_for_long_enough_is_not_that_face() -> None:
    tracks = TrackList()
    co = CoSightings(tracks, IdentityStats(), overlap_s=1.0)
    _seen(tracks, 1, 0.0, 0.8, face=7)  # Alice's track
    _seen(tracks, 2, 0.2, 0.8)  # someone beside her: 0.6 s together, not yet enough
    co.note()
    assert not co.excludes(2, 7)
    _seen(tracks, 1, 1.5)
    _seen(tracks, 2, 1.6)  # 1.3 s together
    co.note()
    assert co.excludes(2, 7) and tracks.entries[1].not_faces == set()


def test_a_person_handed_from_one_track_to_the_next_is_not_excluded_from_their_face() -> None:
    tracks = TrackList()
    co = CoSightings(tracks, IdentityStats(), overlap_s=1.0)
    _seen(tracks, 1, 0.0, 5.0, face=7)  # Alice's track, last seen at 5 s
    _seen(tracks, 2, 5.3, 9.0)  # her next track begins just after: never seen together
    co.note()
    assert not co.excludes(2, 7)


def test_only_a_crossing_or_stray_that_makes_another_person_likelier_than_not_forgets_what_was_seen_alongside(
        ) -> None:
    tracks = TrackList()
    co, crossings = CoSightings(tracks, IdentityStats(), overlap_s=1.0), Crossings(tracks)
    _seen(tracks, 1, 0.0, 3.0, face=7)  # Alice's track
    _seen(tracks, 2, 0.0, 3.0)  # someone beside her
    co.note()
    assert co.excludes(2, 7)
    crossings.crossed(1, 2, 0.45, 3.0)  # the tracker may have swapped them: still less likely than not
    crossings.strayed(2, 0.05)
    assert co.excludes(2, 7)
    crossings.strayed(2, 0.2)  # now track 2 more likely follows another person (who may be Alice)
    assert crossings.doubt_of(2) > 0.5
    assert not co.excludes(2, 7) and tracks.entries[2].person_since_s == 3.0
    _seen(tracks, 1, 3.5)
    _seen(tracks, 2, 3.5)
    co.note()  # seen alongside again, but only for 0.5 s since
    assert not co.excludes(2, 7)
