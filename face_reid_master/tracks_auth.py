"""Authenticated /tracks_named: what a secured master seals its tracks for, and how a consumer checks them.

A master with a network key publishes its NamedTrackArray sealed (AES-256-GCM with the network key,
:mod:`face_reid_camera.common.sealing`, purpose ``"tracks"``: a sealed camera frame or admin request cannot be
passed off as tracks) on ``<tracks_topic>_sealed`` and nothing on the plain topic: a participant without the
key can neither forge nor replay tracks, and a consumer with the key takes only sealed ones. The key
authenticates the network, not the master: any holder of it (a camera host too) could seal tracks. Pure Python
(no rclpy): the ROS side is :mod:`face_reid_master.ros.tracks_in`.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from face_reid_camera.common.sealing import Opener, Sealed, SealError

__all__ = ["KEY_HINT", "SEALED_SUFFIX", "TRACKS_PURPOSE", "NetworkCheck", "TracksVerifier", "check_network",
           "sealed_topic"]

TRACKS_PURPOSE = "tracks"  # the seal's purpose (in its authenticated data): not "frames", not a request's
SEALED_SUFFIX = "_sealed"
SEALED_TYPE = "face_reid_msgs/msg/Sealed"
TRACKS_TYPE = "face_reid_msgs/msg/NamedTrackArray"


def sealed_topic(tracks_topic: str) -> str:
    """Where a secured master publishes the tracks it would publish on ``tracks_topic`` (``/tracks_named`` ->
    ``/tracks_named_sealed``)."""
    return tracks_topic.rstrip("/") + SEALED_SUFFIX


@dataclass
class TracksVerifier:
    """Opens sealed tracks (the serialized NamedTrackArray) and counts what it refuses by reason (the
    subscription counts what it accepts: a payload that opens may still hold no NamedTrackArray).

    ``max_age_s``: tracks sealed further than this from this host's clock are refused (``stale``);
    ``not_before_s``: tracks sealed before this (default: now, the consumer's start) are refused (``replayed``):
    what was captured before a restart is not accepted after it.
    """

    key: bytes
    max_age_s: float = 30.0
    not_before_s: float | None = None
    refused: dict[str, int] = field(default_factory=dict)
    _opener: Opener | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        start = time.time() if self.not_before_s is None else self.not_before_s
        self._opener = Opener(self.key, TRACKS_PURPOSE, self.max_age_s, start)

    def open(self, sealed: Sealed, now_s: float | None = None) -> bytes:
        """The serialized NamedTrackArray inside ``sealed``; :class:`SealError` (counted in :attr:`refused`) when
        it must not be used: not sealed with this key for tracks (``forged``), a counter already seen or from
        before the start (``replayed``), too far from this host's clock (``stale``), ``malformed``."""
        assert self._opener is not None
        try:
            return self._opener.open(sealed, now_s)
        except SealError as exc:
            self.refuse(exc.code)
            raise

    def refuse(self, reason: str) -> int:
        """Count one refused message; the count of ``reason`` so far."""
        self.refused[reason] = self.refused.get(reason, 0) + 1
        return self.refused[reason]


@dataclass(frozen=True)
class NetworkCheck:
    """What a consumer of ``topic`` should know about the tracks topics on the network."""

    secured_network: bool  # the sealed tracks topic exists (a secured master publishes there)
    plain_publishers: int  # publishers of the plain topic
    problem: str  # '' = none; else one line for the log (an error without the key, a warning with it)


KEY_HINT = "set network_key_path (the key file of the network)"  # how a node is given the key


def check_network(topics: Iterable[tuple[str, Iterable[str]]], topic: str, have_key: bool,
                  plain_publishers: int, key_hint: str = KEY_HINT) -> NetworkCheck:
    """The state of the tracks topics for a consumer of ``topic`` (with or without the network key), from the
    graph's ``(name, types)`` pairs and the plain topic's publisher count; ``key_hint``: how this consumer is
    given the key (a node's parameter, a tool's argument)."""
    sealed = sealed_topic(topic)
    secured = any(name == sealed and SEALED_TYPE in types for name, types in topics)
    problem = ""
    if not have_key and secured:
        problem = (f"tracks are sealed: {sealed} carries this network's tracks sealed with its key; {key_hint} "
                   f"to read them. Tracks on {topic} are refused meanwhile: a secured master does not publish there, "
                   "so they can only be spoofed")
    elif have_key and plain_publishers:
        problem = (f"{plain_publishers} publisher(s) of unsealed tracks on {topic}: ignored (this consumer has the "
                   f"network key and takes only tracks sealed with it, on {sealed}); an unsecured master, or a "
                   "spoof")
    return NetworkCheck(secured, plain_publishers, problem)
