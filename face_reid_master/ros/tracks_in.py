"""Subscribe to the master's tracks the right way for this network (every consumer of /tracks_named uses this).

With the network key (``key_path``): only ``<topic>_sealed`` is read, each message opened with the key and
checked (:class:`~face_reid_master.tracks_auth.TracksVerifier`: forged, replayed, stale and malformed ones are
refused and counted); plain tracks are never taken, and a warning says when someone publishes them. Without
it: the plain topic is read, but when a sealed tracks topic exists (a secured master's network) an ERROR says
the key is needed and plain tracks are refused (there they can only be spoofed). The callback gets a verified
face_reid_msgs/NamedTrackArray. :class:`OwnTopicListener` is the master's: whether others publishing its
sealed tracks topic hold the key.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from face_reid_camera.common.checks import shown
from face_reid_camera.common.ros.sealed import unpack
from face_reid_camera.common.sealing import SealError, load_network_key
from face_reid_master.tracks_auth import KEY_HINT, NetworkCheck, TracksVerifier, check_network, sealed_topic
from face_reid_msgs.msg import NamedTrackArray
from face_reid_msgs.msg import Sealed as SealedMsg

__all__ = ["MAX_SEALED_TRACKS_BYTES", "OwnTopicListener", "TracksSubscription", "subscribe_tracks"]

# A sealed tracks message larger than this is refused unread (a NamedTrack is ~300 bytes: 4 MiB is >10,000 tracks).
MAX_SEALED_TRACKS_BYTES = 4 << 20
_REPEAT_PROBLEM_S = 30.0  # a network problem (e.g. no key on a secured network) is logged again this often
_LOG_REFUSED_S = 5.0  # refused messages are logged at most this often


class TracksSubscription:
    """A subscription to the master's tracks; see the module docstring. :attr:`accepted` and :attr:`refused`
    (by reason) count messages; :attr:`network` is the last :meth:`check`."""

    def __init__(self, node: Any, callback: Callable[[Any], None], topic: str = "/tracks_named",
                 key_path: str | Path = "", qos: QoSProfile | None = None, max_age_s: float = 30.0,
                 check_period_s: float = 2.0, on_refused: Callable[[str, str], None] | None = None,
                 callback_group: Any = None, key_hint: str = KEY_HINT) -> None:
        self.node, self.topic, self.key_hint = node, topic, key_hint
        self._callback, self._on_refused = callback, on_refused
        self.verifier = TracksVerifier(load_network_key(key_path), max_age_s) if key_path else None
        self.refused: dict[str, int] = self.verifier.refused if self.verifier is not None else {}
        self.accepted = 0
        self.network: NetworkCheck | None = None
        self._problem, self._problem_logged_s = "", -float("inf")
        self._refusal_logged_s = -float("inf")
        qos = qos or QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        if self.verifier is not None:
            self.listening = sealed_topic(topic)
            self._sub = node.create_subscription(SealedMsg, self.listening, self._on_sealed, qos, raw=True,
                                                 callback_group=callback_group)
        else:
            self.listening = topic
            self._sub = node.create_subscription(NamedTrackArray, topic, self._on_plain, qos,
                                                 callback_group=callback_group)
        self._timer = node.create_timer(check_period_s, self.check, callback_group=callback_group)

    def destroy(self) -> None:
        """Drop the subscription and its timer."""
        self.node.destroy_subscription(self._sub)
        self.node.destroy_timer(self._timer)

    def check(self) -> NetworkCheck:
        """Look at the tracks topics on the network; log a problem when it appears, then every 30 s (an ERROR
        without the key, a warning with it)."""
        self.network = check_network(self.node.get_topic_names_and_types(), self.topic, self.verifier is not None,
                                     self.node.count_publishers(self.topic), self.key_hint)
        problem, now = self.network.problem, time.monotonic()
        if problem and (problem != self._problem or now - self._problem_logged_s >= _REPEAT_PROBLEM_S):
            if self.verifier is not None:  # a line per severity: rclpy refuses another severity from the same line
                self.node.get_logger().warning(problem)
            else:
                self.node.get_logger().error(problem)
            self._problem_logged_s = now
        self._problem = problem
        return self.network

    def _refuse(self, reason: str, message: str) -> None:
        if self.verifier is None:
            self.refused[reason] = self.refused.get(reason, 0) + 1
        if self._on_refused is not None:
            self._on_refused(reason, message)
            return
        now = time.monotonic()
        if now - self._refusal_logged_s >= _LOG_REFUSED_S:
            self._refusal_logged_s = now
            counts = ", ".join(f"{k}: {v}" for k, v in sorted(self.refused.items()))
            self.node.get_logger().warning(f"{message} [refused so far: {counts}]")

    def _on_plain(self, msg: Any) -> None:
        network = self.network if self.network is not None else self.check()
        if network.secured_network:
            self._refuse("unauthenticated", f"tracks on {self.topic} refused: this network's tracks are sealed "
                                            f"(on {sealed_topic(self.topic)}): {self.key_hint}")
            return
        self.accepted += 1
        self._callback(msg)

    def _on_sealed(self, raw: bytes) -> None:
        assert self.verifier is not None
        if len(raw) > MAX_SEALED_TRACKS_BYTES:
            self.verifier.refuse("oversized")
            self._refuse("oversized", f"sealed tracks of {len(raw)} bytes refused unread")
            return
        try:
            sealed = unpack(deserialize_message(raw, SealedMsg))
        except Exception as exc:
            self.verifier.refuse("malformed")
            self._refuse("malformed", f"not a face_reid_msgs/Sealed on {self.listening}: {str(exc)[:200]}")
            return
        try:
            payload = self.verifier.open(sealed)
        except SealError as exc:
            self._refuse(exc.code, f"sealed tracks from {shown(sealed.sender_id, 64)} refused: {exc}")
            return
        try:
            msg = deserialize_message(payload, NamedTrackArray)
        except Exception as exc:  # a key holder sealed something else
            self.verifier.refuse("malformed")
            self._refuse("malformed", f"sealed tracks from {shown(sealed.sender_id, 64)} hold no NamedTrackArray: "
                                      f"{str(exc)[:200]}")
            return
        self.accepted += 1
        self._callback(msg)


def subscribe_tracks(node: Any, callback: Callable[[Any], None], topic: str = "/tracks_named",
                     key_path: str | Path = "", **options: Any) -> TracksSubscription:
    """The master's tracks for ``callback`` (a verified face_reid_msgs/NamedTrackArray each): sealed ones opened
    with the network key in ``key_path`` ('' = none: plain ones); ``options``: see :class:`TracksSubscription`."""
    return TracksSubscription(node, callback, topic, key_path, **options)


class OwnTopicListener:
    """What others publish on a secured master's own sealed tracks topic: while :meth:`listen` is told that others
    publish there, counts the messages of other senders that open with the network key (:attr:`opened`: another
    master) and those that do not (:attr:`unopened`: a keyless participant). The master's own messages
    (``own_sender``) are opened and not counted. Unsecured (no key configured) it never listens."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.key: bytes | None = None
        self.own_sender, self.max_age_s = "", 30.0
        self.opened = self.unopened = 0
        self.verifier: TracksVerifier | None = None
        self._sub: Any = None

    def configure(self, key: bytes | None, own_sender: str, max_age_s: float) -> None:
        self.key, self.own_sender, self.max_age_s = key, own_sender, max_age_s

    def others(self, topic: str) -> list[str]:
        """The other publishers of ``topic`` (namespaced node names; the master itself once), listened to while
        they exist ('' = none)."""
        others = [f"{info.node_namespace.rstrip('/')}/{info.node_name}"
                  for info in self.node.get_publishers_info_by_topic(topic)] if topic else []
        mine = f"{self.node.get_namespace().rstrip('/')}/{self.node.get_name()}"
        if mine in others:  # ours, once: a second master of the same name is another entry
            others.remove(mine)
        self.listen(topic, bool(others))
        return others

    def listen(self, topic: str, others: bool) -> None:
        """Listen to ``topic`` while ``others`` publish it (and a key is configured); stop when they are gone."""
        if others and self._sub is None and self.key is not None and topic:
            self.verifier = TracksVerifier(self.key, self.max_age_s)
            self.opened = self.unopened = 0
            qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
            self._sub = self.node.create_subscription(SealedMsg, topic, self._on_sealed, qos, raw=True)
        elif not others and self._sub is not None:
            self.node.destroy_subscription(self._sub)
            self._sub = None

    def _on_sealed(self, raw: bytes) -> None:
        if len(raw) > MAX_SEALED_TRACKS_BYTES or self.verifier is None:
            self.unopened += 1
            return
        try:
            sealed = unpack(deserialize_message(raw, SealedMsg))
            self.verifier.open(sealed)
        except Exception:  # not a Sealed, or not sealed with the key (forged, replayed, stale)
            self.unopened += 1
            return
        if sealed.sender_id != self.own_sender:
            self.opened += 1
