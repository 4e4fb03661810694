"""The camera topics a master node subscribes to.

A fixed list (``camera_topics``) and, every ``topic_discovery_period_s``, each discovered topic of the camera
message type matching a regex; at most ``max_camera_topics`` (DDS buffers per topic: memory before any
message is authenticated) and, with ``known_camera_ids``, only topics one of whose namespaces is a known
camera. A refused topic is counted and said once. Subscriptions take raw CDR bytes (the node reads them) and
carry no QoS-event handlers; instead, a topic whose publishers exist but none matches (a best-effort camera)
is said once.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks

from face_reid_camera.common.checks import shown
from face_reid_msgs.msg import CameraFrame, Sealed

__all__ = ["CameraTopics"]


class CameraTopics:
    """The subscriptions of a master ``node`` to camera topics (see the module doc). ``on_message`` gets each
    message's CDR bytes; ``reject(code, message)`` counts and logs a refused topic."""

    def __init__(self, node: Any, on_message: Callable[[bytes], None], reject: Callable[[str, str], None]) -> None:
        self.node = node
        self.on_message = on_message
        self.reject = reject
        self.subscribed: dict[str, Any] = {}
        self.unmatched: set[str] = set()  # topics said to have only publishers that do not match
        self.refused: set[str] = set()  # topics not subscribed (cap reached, unknown camera)
        self.regex: re.Pattern[str] | None = None
        self.max_topics = 0
        self.known_cameras: frozenset[str] = frozenset()  # known_camera_ids ({} = any)
        self.sealed = False  # the messages are Sealed (a secured network), not CameraFrame
        self.qos: Any = None

    def configure(self, regex: re.Pattern[str] | None, max_topics: int, known_cameras: frozenset[str],
                  sealed: bool) -> None:
        """``regex``: discovered topics matching it are subscribed (None: only the fixed list)."""
        self.regex = regex
        self.max_topics = max_topics
        self.known_cameras = known_cameras
        self.sealed = sealed

    def subscribe(self, topic: str) -> None:
        if topic in self.subscribed or topic in self.refused:
            return
        if len(self.subscribed) >= self.max_topics:  # memory before authentication: DDS buffers per topic
            self.refused.add(topic)
            self.reject("topic_cap", f"camera topic {shown(topic, 128)} not subscribed: already "
                                     f"{len(self.subscribed)} camera topics (max_camera_topics)")
            return
        # Without rclpy's default QoS-event handlers (two per subscription, each walked by the executor on every
        # cycle): publishers that do not match are found by warn_unmatched instead.
        events = SubscriptionEventCallbacks(use_default_callbacks=False)
        self.subscribed[topic] = self.node.create_subscription(Sealed if self.sealed else CameraFrame, topic,
                                                               self.on_message, self.qos, event_callbacks=events,
                                                               raw=True)
        self.node.get_logger().info(f"subscribed to camera topic {topic}")

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

    def discover(self) -> None:
        self.warn_unmatched()
        if self.regex is None:
            return
        for name, types in self.node.get_topic_names_and_types():
            wanted = "face_reid_msgs/msg/Sealed" if self.sealed else "face_reid_msgs/msg/CameraFrame"
            if wanted in types and self.regex.search(name) and name not in self.refused:
                if self.known_cameras and self.known_cameras.isdisjoint(name.split("/")):
                    self.refused.add(name)  # a stranger's topic: not even buffered
                    self.reject("topic_unknown_camera", f"camera topic {shown(name, 128)} not subscribed: none of "
                                "its namespaces is a known_camera_ids entry (list it in camera_topics)")
                    continue
                self.subscribe(name)

    def status(self) -> tuple[dict[str, object], list[str]]:
        """Their counts for /diagnostics and the warnings those call for."""
        counts: dict[str, object] = {"camera_topics": len(self.subscribed),
                                     "camera_topics_unmatched": len(self.unmatched),
                                     "camera_topics_refused": len(self.refused)}
        warnings = [] if self.subscribed else ["no camera topic found yet"]
        if self.refused:
            warnings.append(f"{len(self.refused)} camera topic(s) not subscribed (max_camera_topics reached, or not "
                            f"named after a known camera), e.g. {shown(min(self.refused), 64)}")
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
        self.refused.clear()
