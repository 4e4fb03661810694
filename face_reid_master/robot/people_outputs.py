"""What the optional robot-stack people topics carry, from the master's tracks (pure: no ROS).

``/people`` (people_msgs/People, read by nav2 social costmap layers): one entry per published track with a name,
position, velocity, reliability and tags. REP-155 (ROS4HRI): ``/humans/persons/tracked`` lists person ids and
each person has latched sub-topics (``anonymous``, ``face_id``, ``name``, ``location_confidence``, ``alias``).
Person ids: ``face<face_id>`` for an identified track (stable across restarts, like the face id), ``anon<track_id>``
while the face is unknown (REP-155 anonymous persons; when the face is decided the anonymous id gets an ``alias``
to the new one). Tentative tracks are left out; lost tracks (a predicted position) are kept with a lower
reliability / location confidence and the tag ``state=lost``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, NamedTrackRecord
from face_reid_master.robot.frames import PlanarTransform, load_world_to_map

__all__ = ["HriPerson", "HriUpdate", "PeopleOutputConfig", "PeopleOutputs", "PersonOut", "hri_person_id"]

_STATE_NAMES = {STATE_CONFIRMED: "confirmed", STATE_LOST: "lost"}


@dataclass
class PeopleOutputConfig:
    """The master's optional people outputs (node parameters, declared here once)."""

    publish_people: bool = param(
        False, "Also publish people_msgs/People on people_topic (nav2 social costmap layers) when people_msgs is "
        "installed (bool; not installed: one warning, nothing else changes).")
    people_topic: str = param("/people", "Where people_msgs/People is published (with publish_people).")
    publish_hri: bool = param(
        False, "Also publish the ROS4HRI REP-155 person topics (/humans/persons/tracked and "
        "/humans/persons/<id>/...) when hri_msgs is installed (bool; not installed: one warning).")
    people_world_to_map_path: str = param(
        "", "world->map transform file written by face-reid-align-map: /people positions and velocities are then "
        "in its map frame ('' = the world frame).")
    people_lost_reliability: float = param(
        0.3, "/people reliability and REP-155 location_confidence of a lost track, whose position is a prediction "
        "(0..1; a confirmed track has 1).", low=0.0, high=1.0)
    hri_forget_after_s: float = param(
        10.0, "A REP-155 person's sub-topics are removed this long after it was last tracked (s).",
        low=0.0, high=86400.0)
    hri_max_persons: int = param(
        64, "At most this many REP-155 persons keep their sub-topics (count; the longest gone are removed first).",
        low=1, high=100000)

    def __post_init__(self) -> None:
        validate_fields(self)


def hri_person_id(face_id: int, track_id: int) -> str:
    """The REP-155 person id of a track: ``face<face_id>`` when identified, else ``anon<track_id>``."""
    return f"face{int(face_id)}" if face_id else f"anon{int(track_id)}"


@dataclass(frozen=True)
class PersonOut:
    """One person of ``/people`` (and of REP-155 unless ``hri`` is False), in the output frame."""

    track_id: int
    face_id: int  # 0 = unknown (an anonymous REP-155 person)
    person_id: str  # REP-155 person id
    name: str  # predefined name, else face_<id>, else track_<id>
    known_name: str  # the predefined name ("" = none)
    position_xyz_m: tuple[float, float, float]
    velocity_xyz_mps: tuple[float, float, float]
    reliability: float  # 1 = seen now, people_lost_reliability = lost (position predicted)
    identity_confidence: float  # 0..1
    lost: bool
    tagnames: tuple[str, ...]
    tags: tuple[str, ...]
    hri: bool = True  # False: another track of the same face holds the REP-155 person


@dataclass(frozen=True)
class HriPerson:
    """What a REP-155 person's latched sub-topics carry."""

    person_id: str
    anonymous: bool
    face_id: str  # "" = no face (an anonymous person)
    name: str  # "" = unknown
    location_confidence: float


@dataclass(frozen=True)
class HriUpdate:
    """One REP-155 publish: the tracked ids, every tracked person's sub-topic values, the aliases of anonymous
    persons that got a face (old id -> new id) and the person ids whose sub-topics should now be removed."""

    tracked: tuple[str, ...]
    persons: tuple[HriPerson, ...]
    aliases: dict[str, str]
    removed: tuple[str, ...]


class PeopleOutputs:
    """Tracks -> /people entries and REP-155 updates; remembers REP-155 persons to say who appeared, was merged or
    is gone (bounded by ``hri_max_persons``)."""

    def __init__(self, config: PeopleOutputConfig | None = None) -> None:
        self.config = config if config is not None else PeopleOutputConfig()
        self.transform: PlanarTransform | None = None
        self.map_frame = ""
        if self.config.people_world_to_map_path:
            self.transform, _, self.map_frame = load_world_to_map(self.config.people_world_to_map_path)
        self._last_tracked_s: dict[str, float] = {}  # REP-155 person id -> last time it was tracked
        self._track_person: dict[int, str] = {}  # track id -> its person id at the last update

    def frame_id(self, world_frame_id: str) -> str:
        """The frame of the outputs: the map frame of the world->map file, else the world frame."""
        return self.map_frame or world_frame_id

    def people(self, tracks: Iterable[NamedTrackRecord]) -> list[PersonOut]:
        """The /people entries: confirmed and lost tracks (tentative and bad ones left out), in the output frame."""
        out: list[PersonOut] = []
        holder: dict[int, int] = {}  # face id -> index in out of the track that holds its REP-155 person
        for tr in tracks:
            if tr.state not in _STATE_NAMES:
                continue
            pos = np.asarray(tr.position_xy, dtype=np.float64).reshape(-1)[:2]
            vel = np.asarray(tr.velocity_xy, dtype=np.float64).reshape(-1)[:2]
            if pos.size != 2 or not np.all(np.isfinite(pos)):
                continue  # nowhere to put it
            vel = vel if vel.size == 2 and np.all(np.isfinite(vel)) else np.zeros(2)
            if self.transform is not None:
                pos, vel = self.transform.apply(pos), self.transform.rotate(vel)
            lost = tr.state == STATE_LOST
            reliability = self.config.people_lost_reliability if lost else 1.0
            face_id, track_id = int(tr.face_id), int(tr.track_id)
            person_id = hri_person_id(face_id, track_id)
            name = tr.name or (f"face_{face_id}" if face_id else f"track_{track_id}")
            confidence = float(tr.identity_confidence) if math.isfinite(tr.identity_confidence) else 0.0
            tagnames = ("person_id", "track_id", "face_id", "state", "identity_confidence", "identity_evidence")
            tags = (person_id, str(track_id), str(face_id), _STATE_NAMES[tr.state], f"{confidence:.3f}",
                    tr.identity_evidence)
            person = PersonOut(track_id, face_id, person_id, name, tr.name, (float(pos[0]), float(pos[1]), 0.0),
                               (float(vel[0]), float(vel[1]), 0.0), reliability, confidence, lost, tagnames, tags)
            if face_id and face_id in holder:  # two tracks of one face: one REP-155 person, the better track's
                other = out[holder[face_id]]
                if (other.lost, -other.identity_confidence) <= (lost, -confidence):
                    out.append(_without_hri(person))
                    continue
                out[holder[face_id]] = _without_hri(other)
            if face_id:
                holder[face_id] = len(out)
            out.append(person)
        return out

    def hri(self, people: Iterable[PersonOut], now_s: float) -> HriUpdate:
        """The REP-155 update for the /people entries of one publish at ``now_s`` (s; any monotonic clock)."""
        persons = [p for p in people if p.hri]
        tracked = tuple(p.person_id for p in persons)
        aliases: dict[str, str] = {}
        current: dict[int, str] = {}
        for p in persons:
            current[p.track_id] = p.person_id
            self._last_tracked_s[p.person_id] = now_s
            before = self._track_person.get(p.track_id)
            if before is not None and before != p.person_id and before.startswith("anon"):
                aliases[before] = p.person_id  # the anonymous person turned out to be this one
        self._track_person = current
        live = set(tracked)
        gone = sorted((t, pid) for pid, t in self._last_tracked_s.items() if pid not in live)
        removed = [pid for t, pid in gone if now_s - t > self.config.hri_forget_after_s]
        excess = len(self._last_tracked_s) - len(removed) - self.config.hri_max_persons
        if excess > 0:
            removed += [pid for _, pid in gone if pid not in removed][:excess]
        for pid in removed:
            del self._last_tracked_s[pid]
        return HriUpdate(
            tracked,
            tuple(HriPerson(p.person_id, not p.face_id, str(p.face_id) if p.face_id else "", p.known_name,
                            p.reliability) for p in persons),
            aliases, tuple(removed))

    @property
    def hri_known(self) -> tuple[str, ...]:
        """REP-155 persons that still have sub-topics (tracked now or gone for less than hri_forget_after_s)."""
        return tuple(self._last_tracked_s)


def _without_hri(person: PersonOut) -> PersonOut:
    return replace(person, hri=False)
