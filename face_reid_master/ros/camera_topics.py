"""The camera topics a master node subscribes to.

A fixed list (``camera_topics``) and, every ``topic_discovery_period_s``, each discovered topic of the camera
message type matching a regex; with ``known_camera_ids``, only topics whose camera (the innermost namespace above
``face_reid/frames[_sealed]``) is a known id. Which of them are subscribed, and which hold one of the
``max_camera_topics`` slots (DDS buffers per topic: memory before any message is authenticated), is
:class:`~face_reid_master.camera_slots.CameraSlots`'s: on a secured master a discovered topic takes a slot only
once a message on it opened with the network key, and one on probation that does not is released. Refused and
released topics are counted and logged (throttled). Subscriptions take raw CDR bytes (the node reads them) and
carry no QoS-event handlers; instead, a topic whose publishers exist but none matches (a best-effort camera)
is said once.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from functools import partial
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks

from face_reid_camera.common.checks import shown
from face_reid_master.camera_slots import CameraIdWatch, CameraSlots, SlotChanges, camera_of_topic
from face_reid_msgs.msg import CameraFrame, Sealed

__all__ = ["CameraTopics"]

_RELEASE_WARN_S = 60.0  # /diagnostics warns this long after a camera topic was released unauthenticated (s)


class CameraTopics:
    """The subscriptions of a master ``node`` to camera topics (see the module doc). ``on_message`` gets each
    message's CDR bytes and says whether it was received (on a secured network: opened with the key; None: not
    said); ``reject(code, message)`` counts and logs a refused or released topic."""

    def __init__(self, node: Any, on_message: Callable[[bytes, str], bool | None],
                 reject: Callable[[str, str], None]) -> None:
        self.node = node
        self.on_message = on_message
        self.reject = reject
        self.subscribed: dict[str, Any] = {}  # every camera subscription: holding a slot or on probation
        self.unmatched: set[str] = set()  # topics said to have only publishers that do not match
        self.unknown: set[str] = set()  # discovered topics of no known camera: never subscribed
        self.slots = CameraSlots(1, False)
        self.regex: re.Pattern[str] | None = None
        self.known_cameras: frozenset[str] = frozenset()  # known_camera_ids ({} = any)
        self.sealed = False  # the messages are Sealed (a secured network), not CameraFrame
        self.qos: Any = None
        self.clock: Callable[[], float] = time.monotonic
        self.camera_ids = CameraIdWatch()  # two cameras under one camera id (told of frames by the receiver)

    @property
    def refused(self) -> set[str]:
        """Topics not subscribed: no slot left, or not named after a known camera."""
        return self.slots.refused | self.unknown

    def configure(self, regex: re.Pattern[str] | None, max_topics: int, known_cameras: frozenset[str],
                  sealed: bool) -> None:
        """``regex``: discovered topics matching it are subscribed (None: only the fixed list); ``sealed``: a
        secured network (a discovered topic holds a slot only once authenticated)."""
        self.regex = regex
        self.known_cameras = known_cameras
        self.sealed = sealed
        self.slots = CameraSlots(max_topics, authenticate=sealed)

    def subscribe(self, topic: str) -> None:
        """A configured topic (camera_topics): a slot at once while one is free (the configuration is trusted)."""
        if topic in self.subscribed or topic in self.refused:
            return
        if not self.slots.fixed(topic):
            self._refused_for_cap(topic)
            return
        self._subscribe(topic)

    def _subscribe(self, topic: str) -> None:
        if topic in self.subscribed:  # a slot given back and on probation again at once: the same subscription
            return
        # Without rclpy's default QoS-event handlers (two per subscription, each walked by the executor on every
        # cycle): publishers that do not match are found by warn_unmatched instead.
        events = SubscriptionEventCallbacks(use_default_callbacks=False)
        self.subscribed[topic] = self.node.create_subscription(Sealed if self.sealed else CameraFrame, topic,
                                                               partial(self._message, topic), self.qos,
                                                               event_callbacks=events, raw=True)
        on_probation = " (on probation until a message on it opens with the network key)" \
            if topic in self.slots.probation else ""
        self.node.get_logger().info(f"subscribed to camera topic {shown(topic, 128)}{on_probation}")

    def _message(self, topic: str, raw: bytes) -> None:
        received = self.on_message(raw, topic)
        if received is not None:
            self.heard(topic, received)

    def heard(self, topic: str, received: bool) -> None:
        """A message on ``topic`` was received (opened with the key) or refused: a topic on probation takes a slot
        with its first received message, and is released after too many refused ones (at the next discovery)."""
        on_probation = topic in self.slots.probation
        self.slots.heard(topic, received, self.clock())
        if on_probation and topic in self.slots.slots:
            self.node.get_logger().info(f"camera topic {shown(topic, 128)} authenticated: holds camera topic slot "
                                        f"{len(self.slots.slots)} of {self.slots.max_slots}")
        elif on_probation and topic in self.slots.refused:
            self._refused_for_cap(topic)

    def _refused_for_cap(self, topic: str) -> None:
        self.reject("topic_cap", f"camera topic {shown(topic, 128)} not subscribed: already "
                                 f"{len(self.slots.slots)} camera topics (max_camera_topics)")

    def warn_unmatched(self) -> None:
        """Say once per camera topic when it has publishers but none is matched: their QoS is incompatible with the
        master's reliable subscription (a best-effort camera publisher), so its frames never arrive."""
        for topic, sub in self.subscribed.items():
            if sub.get_publisher_count() > 0:
                self.unmatched.discard(topic)
                continue
            offered = self.node.get_publishers_info_by_topic(topic)
            if not offered or topic in self.unmatched:
                continue
            self.unmatched.add(topic)
            policies = sorted({str(info.qos_profile.reliability.name).lower() for info in offered})
            self.node.get_logger().warning(
                f"camera topic {shown(topic, 128)}: {len(offered)} publisher(s) offering reliability "
                f"{'/'.join(policies)} do not match the master's subscription (reliable, depth 50): their frames "
                "are not received; publish camera frames reliable")

    def _publishers(self, topic: str) -> list[str]:
        """The nodes publishing ``topic``: ``/ns/node (participant <GUID prefix>)`` (two camera processes of one
        name and namespace differ by their participant)."""
        infos = self.node.get_publishers_info_by_topic(topic)
        return sorted({f"{info.node_namespace.rstrip('/')}/{info.node_name} (participant "
                       f"{bytes(info.endpoint_gid[:12]).hex()})" for info in infos})

    def _sources(self, topic: str) -> frozenset[str]:
        """The participants publishing ``topic`` (the GUID prefix of each publisher's gid; empty: none)."""
        return frozenset(bytes(info.endpoint_gid[:12]).hex() for info in self.node.get_publishers_info_by_topic(topic))

    def discover(self) -> None:
        """Offer the new camera topics with publishers, then subscribe and unsubscribe what the slots say."""
        self.warn_unmatched()
        now = self.clock()
        if self.regex is not None:
            wanted = "face_reid_msgs/msg/Sealed" if self.sealed else "face_reid_msgs/msg/CameraFrame"
            graph = self.node.get_topic_names_and_types()
            present = {name for name, _ in graph}  # what is gone is forgotten (a stranger's names do not pile up)
            self.slots.prune(present)
            self.unknown &= present
            for name, types in graph:
                if wanted not in types or not self.regex.search(name) or self.slots.known(name) \
                        or name in self.unknown:
                    continue
                if self.known_cameras and camera_of_topic(name) not in self.known_cameras:
                    self.unknown.add(name)  # a stranger's topic: not even buffered
                    self.reject("topic_unknown_camera", f"camera topic {shown(name, 128)} not subscribed: it is not "
                                "<namespace>/<a known_camera_ids entry>/face_reid/... (list it in camera_topics)")
                    continue
                sources = self._sources(name)
                if sources:  # a topic only subscribed to carries no frames
                    self.slots.offer(name, sources, now)
        self._apply(self.slots.step(now, {t: self._sources(t) for t in self.slots.probation}))

    def _apply(self, changes: SlotChanges) -> None:
        for topic in changes.subscribe:
            self._subscribe(topic)
        for topic in changes.refused:
            self._refused_for_cap(topic)
        for topic in changes.idle:
            self.node.get_logger().info(f"camera topic {shown(topic, 128)}: nothing on it opened with the network "
                                        f"key for {self.slots.slot_idle_s:g} s: its slot is given back (offered "
                                        "again while it has publishers)")
        for topic in changes.unsubscribe:
            heard = changes.unopened.get(topic, 0)
            why = f"{heard} message(s), none opened: a keyless publisher" if heard else "nothing heard on it"
            self.reject("topic_released", f"camera topic {shown(topic, 128)} released: no message on it opened with "
                                          f"the network key within {self.slots.probation_s:g} s ({why}); offered "
                                          "again later")
        for topic in [t for t in self.subscribed if t not in self.slots.slots and t not in self.slots.probation]:
            self.node.destroy_subscription(self.subscribed.pop(topic))
            self.unmatched.discard(topic)

    def status(self) -> tuple[dict[str, object], list[str]]:
        """Their counts for /diagnostics and the warnings those call for."""
        slots = self.slots
        counts: dict[str, object] = {"camera_topics": len(slots.slots),
                                     "camera_topics_probation": len(slots.probation),
                                     "camera_topics_waiting": len(slots.waiting),
                                     "camera_topics_unmatched": len(self.unmatched),
                                     "camera_topics_refused": len(self.refused),
                                     "camera_topics_released": slots.released}
        warnings = [] if slots.slots else ["no camera topic found yet" if not slots.probation else
                                           "no camera topic authenticated yet"]
        if self.refused:
            warnings.append(f"{len(self.refused)} camera topic(s) not subscribed (max_camera_topics reached, or not "
                            f"named after a known camera), e.g. {shown(min(self.refused), 64)}")
        if slots.last_release_s is not None and self.clock() - slots.last_release_s <= _RELEASE_WARN_S:
            warnings.append(f"{slots.released} camera topic(s) released so far: nothing on them opened with the "
                            "network key (a keyless or silent publisher on this domain)")
        warnings += self.camera_ids.warnings(time.monotonic(), {t: self._publishers(t) for t in self.subscribed})
        if self.unmatched:
            warnings.append(f"{len(self.unmatched)} camera topic(s) whose publishers do not match the master's "
                            f"reliable subscription, e.g. {shown(min(self.unmatched), 64)}: publish camera frames "
                            "reliable")
        return counts, warnings

    def destroy(self) -> None:
        for sub in self.subscribed.values():
            self.node.destroy_subscription(sub)
        self.subscribed = {}
        self.unmatched.clear()
        self.unknown.clear()
        self.slots.forget()
