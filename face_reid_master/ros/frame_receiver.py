"""Camera messages into the master's next cycle: opened (secured network), read, checked, queued.

A message larger than ``MAX_FRAME_BYTES`` is refused before it is read (memory before authentication); a
sealed one must open with the network key and name the camera that sealed it; a frame that cannot be read is
refused. Every refusal is counted by reason and logged (throttled). A received frame is queued in stamp order
for the next cycle (:class:`~face_reid_master.intake.FrameIntake`), and its transport delay is followed per
camera (:class:`~face_reid_master.clock_offsets.ClockOffsets`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

from rclpy.serialization import deserialize_message

from face_reid_camera.common.checks import shown
from face_reid_camera.common.diagnostics import NodeHealth
from face_reid_camera.common.ros.sealed import open_payload
from face_reid_camera.common.sealing import SealError
from face_reid_master.camera_slots import CameraIdWatch
from face_reid_master.clock_offsets import ClockOffsets
from face_reid_master.intake import FrameIntake, PendingFrame
from face_reid_master.records import CameraFrameRecord
from face_reid_master.ros.convert import frame_from_msg
from face_reid_master.ros.frame_cdr import frame_from_cdr, is_plain_cdr
from face_reid_msgs.msg import CameraFrame, Sealed

__all__ = ["MAX_FRAME_BYTES", "FrameReceiver"]

# A camera message (plain or sealed) larger than this is refused before it is read: a frame of 50 people with
# 256-d embeddings and body descriptors is ~0.2 MB, and the bound keeps what a stranger's traffic costs small.
MAX_FRAME_BYTES = 1 << 20


class FrameReceiver:
    """Reads camera messages into :attr:`intake` (see the module doc). ``openers``: purpose -> Opener when the
    network has a key; ``reject(code, message)`` counts and logs a refusal; ``log_throttled`` as the node's."""

    def __init__(self, health: NodeHealth | None, openers: dict[str, Any], reject: Callable[[str, str], None],
                 log_throttled: Callable[..., None]) -> None:
        self.health = health
        self.openers = openers
        self.reject = reject
        self.log_throttled = log_throttled
        self.intake: FrameIntake[Any] = FrameIntake()
        self.clocks = ClockOffsets()
        self.camera_ids: CameraIdWatch | None = None  # told which topic each received frame's camera id came on

    def receive_sealed(self, raw: bytes, now: float, topic: str = "") -> bool:
        """The CameraFrame inside a sealed message's CDR bytes received (True), or refused (counted by reason,
        logged): an oversized one before it is even read."""
        if self.health is not None:
            self.health.frame_in(now)
        if len(raw) > MAX_FRAME_BYTES:
            self.reject("oversized", f"sealed message of {len(raw)} bytes refused unread (more than "
                                      f"{MAX_FRAME_BYTES})")
            return False
        try:
            sealed = deserialize_message(raw, Sealed)
        except Exception as exc:  # rclpy raises RMWError for bytes that are not one
            self.reject("sealed_malformed", f"not a face_reid_msgs/Sealed: {str(exc)[:200]}")
            return False
        sender = str(sealed.sender_id)
        try:
            payload = open_payload(self.openers["frames"], sealed, time.time())
        except SealError as exc:
            self.reject(f"sealed_{exc.code}", f"sealed frame from {shown(sender, 64)} refused: {exc}")
            return False
        return self.receive(payload, now, sender, counted=True, topic=topic)

    def receive(self, frame: bytes | Any, now: float, sealed_by: str | None = None, counted: bool = False,
                topic: str = "") -> bool:
        """A camera frame (CDR bytes or a CameraFrame message; ``sealed_by``: the sender of the seal it came in)
        read into a record and queued for the next cycle (True); one that cannot be read, or sealed by another
        camera than it names, is refused (counted, logged)."""
        if self.health is not None and not counted:
            self.health.frame_in(now)
        if isinstance(frame, bytes) and len(frame) > MAX_FRAME_BYTES:
            self.reject("oversized", f"camera message of {len(frame)} bytes refused unread (more than "
                                      f"{MAX_FRAME_BYTES})")
            return False
        try:
            record, processing_ms = _read_frame(frame)
        except (ValueError, TypeError, AttributeError) as exc:
            self.reject("malformed" if sealed_by is None else "sealed_malformed", f"malformed CameraFrame: {exc}")
            return False
        if sealed_by is not None and record.camera_id != sealed_by:
            self.reject("sealed_sender_mismatch", f"sealed by {shown(sealed_by, 64)} but says camera "
                                                   f"{shown(record.camera_id, 64)}")
            return False
        self.intake.add(PendingFrame(record.camera_id, record.stamp_s, record))
        if self.camera_ids is not None:  # ``topic``: the camera topic it came on ('' unknown)
            self.camera_ids.frame(record.camera_id, topic, time.monotonic())
        try:
            self.clocks.observe(record.camera_id, record.stamp_s, time.time(), processing_ms * 1e-3)
        except (TypeError, ValueError):
            pass
        return True

    def drain(self, subscriptions: Iterable[Any], now: float,
              heard: Callable[[str, bool], None] | None = None) -> None:
        """Take every message already waiting on the camera subscriptions (not one per executor pass), so that
        one cycle sees all of them and drops the oldest when they are too many; ``heard(topic, received)`` is told
        of each (the camera topic slots count what opened with the key)."""
        for sub in list(subscriptions):
            try:
                with sub.handle:
                    while (taken := sub.handle.take_message(sub.msg_type, True)) is not None:
                        topic = sub.topic_name
                        received = (self.receive_sealed(taken[0], now, topic) if self.openers
                                    else self.receive(taken[0], now, topic=topic))
                        if heard is not None:
                            heard(sub.topic_name, received)
            except Exception as exc:  # a destroyed subscription (deactivating): its messages are gone anyway
                self.log_throttled("drain", f"could not drain {sub.topic_name}: {type(exc).__name__}: {exc}",
                                   1, warn=True)


def _read_frame(frame: bytes | Any) -> tuple[CameraFrameRecord, float]:
    """A camera frame's record and ``processing_time_ms``: CDR bytes read directly (rclpy reads an encoding other
    than plain little-endian CDR), a CameraFrame message converted. ValueError / TypeError when it is not one."""
    if isinstance(frame, bytes):
        if is_plain_cdr(frame):
            return frame_from_cdr(frame)
        try:
            frame = deserialize_message(frame, CameraFrame)
        except Exception as exc:  # rclpy raises RMWError (a RuntimeError) for bytes that are not one
            raise ValueError(f"not a CameraFrame in an encoding rclpy reads: {str(exc)[:200]}") from exc
    return frame_from_msg(frame), float(frame.processing_time_ms)
