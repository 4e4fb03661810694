"""Which camera topics a master listens to, and which of them hold one of its ``max_camera_topics`` slots.

Unsecured (nothing to authenticate), a topic takes a slot when offered while one is free; later ones are refused.
Secured, a discovered topic first goes on probation: subscribed, at most ``probation_topics`` at once (the
longest waiting first), it takes a slot only once a message on it opened with the network key. One that does not
within ``probation_s``, or ``probation_messages`` messages when one participant publishes it (a stranger's
garbage), is released and offered again after a cool-down that doubles on each release: a stranger's keyless
topics cannot fill the slots, and a topic a stranger used before the real camera came still gets its turn. A
topic whose publishers' participants all had a topic released before waits behind the others, so one stranger's
many topics do not hold back a camera that appears after them. A discovered topic holding a slot on which nothing
opened for ``slot_idle_s`` (a camera stopped, or a replayed frame that once got a stranger's topic in) gives its
slot back and is offered again like a new one; topics gone from the graph are forgotten. Pure: the node
subscribes and unsubscribes what :meth:`CameraSlots.step` says.

:class:`CameraIdWatch` finds two cameras under one camera id: frames naming one id on two topics (two camera
nodes given the same ``camera_id`` in different namespaces), or one camera topic published by two nodes (two
cameras started in one namespace); either is a WARN on /diagnostics naming both.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from face_reid_camera.common.checks import shown

__all__ = ["CameraIdWatch", "CameraSlots", "SlotChanges", "camera_of_topic"]

PROBATION_TOPICS = 16  # topics on probation (subscribed, not authenticated) at once
PROBATION_S = 5.0  # a topic on probation with no message opened with the key this long is released (s)
PROBATION_MESSAGES = 20  # ... or after this many messages none of which opened
RETRY_S = 10.0  # a released topic is offered again after this (s), doubled on each further release
RETRY_MAX_S = 160.0  # ... up to this (s)
SLOT_IDLE_S = 60.0  # a discovered topic with no message opened this long gives its slot back (s; cameras publish
#                     every frame, people or not)
MAX_PARTICIPANTS = 4096  # participants remembered as suspected / trusted (the oldest forgotten first)
CAMERA_ID_WINDOW_S = 10.0  # frames of one camera id on two topics within this long: two cameras under one id (s)
MAX_CAMERA_IDS = 1024  # camera ids remembered for that (the least recently heard forgotten first)
CAMERA_TOPIC_DEPTH = 2  # a camera's own topic below its namespace: face_reid/frames or face_reid/frames_sealed


def camera_of_topic(topic: str) -> str:
    """The camera a camera topic belongs to: the innermost namespace above the camera's own two-level topic
    (``/site/cam1/face_reid/frames_sealed`` -> ``cam1``; '' when there is none). ``known_camera_ids`` matches it
    exactly: a name that merely contains a known id elsewhere (``/cam1/x/face_reid/frames_sealed``) is not cam1's."""
    parts = topic.rstrip("/").split("/")
    return parts[-1 - CAMERA_TOPIC_DEPTH] if len(parts) >= CAMERA_TOPIC_DEPTH + 2 else ""


@dataclass
class SlotChanges:
    """What the node does after a :meth:`CameraSlots.step`: ``subscribe`` (put on probation, or given a slot
    unsecured), ``unsubscribe`` (released: not authenticated in time), ``idle`` (a slot given back: nothing opened
    on it for slot_idle_s), ``refused`` (not subscribed: no slot); ``unopened``: how many messages each released
    topic carried (0: a silent publisher)."""

    subscribe: list[str] = field(default_factory=list)
    unsubscribe: list[str] = field(default_factory=list)
    idle: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    unopened: dict[str, int] = field(default_factory=dict)


@dataclass
class _Waiting:
    """A topic waiting for probation: offered again from ``eligible_s``; ``order`` keeps first come first."""

    eligible_s: float
    order: int
    sources: frozenset[str]
    releases: int = 0


@dataclass
class _Probation:
    """A topic on probation since ``since_s``: ``failed`` messages heard on it so far, none opened."""

    since_s: float
    sources: frozenset[str]
    releases: int
    failed: int = 0


class CameraSlots:
    """Slot accounting for camera topics (see the module doc). ``authenticate``: a secured master (probation);
    topic ``sources`` are opaque ids of their publishers' participants (empty: unknown)."""

    def __init__(self, max_slots: int, authenticate: bool, probation_topics: int = PROBATION_TOPICS,
                 probation_s: float = PROBATION_S, probation_messages: int = PROBATION_MESSAGES,
                 retry_s: float = RETRY_S, retry_max_s: float = RETRY_MAX_S, slot_idle_s: float = SLOT_IDLE_S) -> None:
        if max_slots < 1 or probation_topics < 1 or probation_s <= 0 or probation_messages < 1 or retry_s < 0:
            raise ValueError("max_slots, probation_topics, probation_messages >= 1, probation_s > 0, retry_s >= 0")
        self.max_slots, self.authenticate = max_slots, authenticate
        self.probation_topics, self.probation_s, self.probation_messages = (probation_topics, probation_s,
                                                                             probation_messages)
        self.retry_s, self.retry_max_s, self.slot_idle_s = retry_s, retry_max_s, slot_idle_s
        self.slots: dict[str, float | None] = {}  # topic -> when a message on it last opened (None: configured)
        self.probation: dict[str, _Probation] = {}
        self.waiting: dict[str, _Waiting] = {}
        self.refused: set[str] = set()  # never subscribed (no slot unsecured, or an authenticated one beyond the cap)
        self.released = 0  # probation releases so far
        self.last_release_s: float | None = None
        self._suspect: dict[str, None] = {}  # participants that published on a released topic
        self._trusted: dict[str, None] = {}  # participants that published on a topic that authenticated
        self._order = itertools.count()

    def known(self, topic: str) -> bool:
        return topic in self.slots or topic in self.probation or topic in self.waiting or topic in self.refused

    def fixed(self, topic: str) -> bool:
        """A topic from the configuration (camera_topics): a slot at once while one is free (True), else refused."""
        if topic in self.slots or topic in self.probation:
            return True
        self.waiting.pop(topic, None)
        if len(self.slots) >= self.max_slots:
            self.refused.add(topic)
            return False
        self.slots[topic] = None
        return True

    def offer(self, topic: str, sources: frozenset[str], now_s: float) -> None:
        """A discovered camera topic with publishers (``sources``: their participants): queued for the next
        :meth:`step` unless already known."""
        if not self.known(topic):
            self.waiting[topic] = _Waiting(now_s, next(self._order), sources)

    def heard(self, topic: str, authenticated: bool, now_s: float) -> None:
        """A message on ``topic``: opened with the key (``authenticated``: the topic takes a slot if one is free)
        or not (counted towards its release)."""
        if authenticated and self.slots.get(topic) is not None:
            self.slots[topic] = now_s
        entry = self.probation.get(topic)
        if entry is None:
            return
        if authenticated:
            del self.probation[topic]
            _remember(self._trusted, entry.sources)
            if len(self.slots) < self.max_slots:
                self.slots[topic] = now_s
            else:
                self.refused.add(topic)
        else:
            entry.failed += 1

    def step(self, now_s: float, sources_of: dict[str, frozenset[str]] | None = None) -> SlotChanges:
        """Release the topics whose probation is over, then admit waiting ones (probation secured, a slot
        unsecured); ``sources_of``: the current publishers' participants of topics, where known."""
        out = SlotChanges()
        for topic, last_s in list(self.slots.items()):
            if last_s is not None and now_s - last_s >= self.slot_idle_s:  # offered again, as a new topic is
                del self.slots[topic]
                out.idle.append(topic)
        for topic, entry in list(self.probation.items()):
            sources = (sources_of or {}).get(topic, entry.sources)
            # garbage ends a probation early only on a topic of one participant: with several (a camera and a
            # stranger flooding its topic) the camera's frames get the whole probation_s to open
            noisy = entry.failed >= self.probation_messages and len(sources) <= 1
            if noisy or now_s - entry.since_s >= self.probation_s:
                del self.probation[topic]
                _remember(self._suspect, sources - self._trusted.keys())
                delay = min(self.retry_max_s, self.retry_s * 2 ** entry.releases)
                self.waiting[topic] = _Waiting(now_s + delay, next(self._order), sources, entry.releases + 1)
                self.released += 1
                self.last_release_s = now_s
                out.unsubscribe.append(topic)
                out.unopened[topic] = entry.failed
        if sources_of:
            for topic, sources in sources_of.items():
                if topic in self.waiting and sources:
                    self.waiting[topic].sources = sources
        for topic in self._admissible(now_s):
            entry = self.waiting.pop(topic)
            if not self.authenticate:
                if len(self.slots) < self.max_slots:
                    self.slots[topic] = None
                    out.subscribe.append(topic)
                else:
                    self.refused.add(topic)
                    out.refused.append(topic)
                continue
            if len(self.slots) >= self.max_slots or len(self.probation) >= self.probation_topics:
                if len(self.slots) >= self.max_slots:  # every slot authenticated: a topic too many
                    self.refused.add(topic)
                    out.refused.append(topic)
                    continue
                self.waiting[topic] = entry
                break
            self.probation[topic] = _Probation(now_s, entry.sources, entry.releases)
            out.subscribe.append(topic)
        return out

    def _admissible(self, now_s: float) -> list[str]:
        """Waiting topics due now, in the order they are admitted: those with a publisher not yet suspected
        first, then first come first."""
        due = [(self._suspected(w.sources), w.eligible_s, w.order, t) for t, w in self.waiting.items()
               if w.eligible_s <= now_s]
        return [t for *_, t in sorted(due)]

    def _suspected(self, sources: frozenset[str]) -> bool:
        return bool(sources) and sources <= self._suspect.keys()

    def prune(self, present: set[str]) -> None:
        """Forget the waiting and refused topics that are gone from the graph (``present``: the topics there)."""
        for topic in [t for t in self.waiting if t not in present]:
            del self.waiting[topic]
        self.refused &= present

    def forget(self) -> None:
        """Everything (the node's subscriptions are gone: deactivated)."""
        self.slots.clear()
        self.probation.clear()
        self.waiting.clear()
        self.refused.clear()


def _remember(seen: dict[str, None], ids: frozenset[str]) -> None:
    """Add ``ids`` to ``seen`` (insertion-ordered), keeping the newest MAX_PARTICIPANTS."""
    for i in ids:
        seen.pop(i, None)
        seen[i] = None
    while len(seen) > MAX_PARTICIPANTS:
        del seen[next(iter(seen))]


class CameraIdWatch:
    """Two cameras under one camera id (see the module doc): :meth:`frame` is told of each received frame's camera
    id and topic, :meth:`warnings` says what was found (``window_s``: how recent the frames must be)."""

    def __init__(self, window_s: float = CAMERA_ID_WINDOW_S, max_ids: int = MAX_CAMERA_IDS) -> None:
        self.window_s, self.max_ids = window_s, max_ids
        self._topics: dict[str, dict[str, float]] = {}  # camera id -> topic -> when a frame of it last came there

    def frame(self, camera_id: str, topic: str, now_s: float) -> None:
        """A received frame naming ``camera_id`` came on ``topic``."""
        if not topic:
            return
        topics = self._topics.pop(camera_id, None) or {}
        self._topics[camera_id] = topics  # most recently heard last
        topics[topic] = now_s
        if len(topics) > 8:  # one id on many topics: the 8 most recent are enough to name it
            del topics[min(topics, key=topics.__getitem__)]
        while len(self._topics) > self.max_ids:
            del self._topics[next(iter(self._topics))]

    def warnings(self, now_s: float, publishers: Mapping[str, Sequence[str]] | None = None) -> list[str]:
        """One line per camera id heard on two topics within ``window_s``, and per camera topic that
        ``publishers`` (topic -> its publishers, e.g. ``/cam1/face_reid_camera (participant 01ab...)``) gives more
        than one of."""
        out = []
        for camera_id, topics in list(self._topics.items()):
            recent = sorted(t for t, last in topics.items() if now_s - last <= self.window_s)
            if not recent:
                del self._topics[camera_id]
            elif len(recent) > 1:
                out.append(f"camera id {shown(camera_id, 64)} is used by {len(recent)} cameras: frames naming it come "
                           f"on {' and '.join(shown(t, 128) for t in recent[:4])}; give each camera its own camera_id "
                           "(the master takes them for one camera)")
        for topic, nodes in sorted((publishers or {}).items()):
            if len(nodes) > 1:
                out.append(f"camera topic {shown(topic, 128)} is published by {len(nodes)} nodes: "
                           f"{' and '.join(shown(n, 128) for n in sorted(nodes)[:4])}; two cameras started with one "
                           "namespace (or another participant publishing on its topic): give each camera its own "
                           "namespace and camera_id")
        return out
