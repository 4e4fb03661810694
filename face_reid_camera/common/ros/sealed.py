"""ROS messages <-> sealed messages (face_reid_msgs/Sealed): serialize, seal; open, deserialize.

Used by the camera node (frames), the master (frames, admin requests) and admin clients. The cryptography is
in :mod:`face_reid_camera.common.sealing`.
"""

from __future__ import annotations

from typing import Any

from face_reid_camera.common.sealing import Opener, Sealed, Sealer, SealError

__all__ = ["open_message", "open_payload", "open_request", "seal_message", "seal_payload", "seal_request", "unpack"]


def seal_message(sealer: Sealer, msg: Any, purpose: str | None = None) -> Any:
    """``msg`` serialized and sealed (for ``purpose``, default the sealer's), as a face_reid_msgs/Sealed."""
    from rclpy.serialization import serialize_message

    return seal_payload(sealer, serialize_message(msg), purpose)


def seal_payload(sealer: Sealer, payload: bytes, purpose: str | None = None) -> Any:
    """Bytes already serialized (e.g. the master's tracks) sealed, as a face_reid_msgs/Sealed."""
    from face_reid_msgs.msg import Sealed as SealedMsg

    sealed = sealer.seal(payload, purpose)
    return SealedMsg(sender_id=sealed.sender_id, counter=sealed.counter, nonce=sealed.nonce,
                     ciphertext=sealed.ciphertext)


def unpack(sealed_msg: Any) -> Sealed:
    """The :class:`Sealed` record of a face_reid_msgs/Sealed message (nothing checked yet)."""
    return Sealed(str(sealed_msg.sender_id), int(sealed_msg.counter), bytes(sealed_msg.nonce),
                  bytes(sealed_msg.ciphertext))


def open_message(opener: Opener, sealed_msg: Any, msg_type: type, now_s: float | None = None,
                 purpose: str | None = None) -> Any:
    """The message of type ``msg_type`` inside a face_reid_msgs/Sealed; :class:`SealError` when it must not be
    used (not sealed with this key, replayed, stale, or not a ``msg_type`` inside)."""
    from rclpy.serialization import deserialize_message

    payload = open_payload(opener, sealed_msg, now_s, purpose)
    try:
        return deserialize_message(payload, msg_type)
    except Exception as exc:  # a key holder sealed something else
        raise SealError("malformed", f"the sealed payload is not a {msg_type.__name__}: {exc}") from exc


def open_payload(opener: Opener, sealed_msg: Any, now_s: float | None = None, purpose: str | None = None) -> bytes:
    """The serialized message inside a face_reid_msgs/Sealed (not read: the caller knows its type);
    :class:`SealError` when it must not be used (not sealed with this key, replayed, stale)."""
    return opener.open(unpack(sealed_msg), now_s, purpose)


def _request_purpose(request: Any) -> str:
    """A seal made for one service (e.g. ``AddPerson_Request``) is not valid for another, nor as a frame."""
    return f"request:{type(request).__module__}.{type(request).__name__}"


def seal_request(sealer: Sealer, request: Any) -> Any:
    """A service request whose ``sealed_request`` field carries the request itself, sealed for that service
    (plain fields cleared: on the wire only the sealed copy says what is asked)."""
    plain = type(request)()
    request.sealed_request = plain.sealed_request  # serialized with the field empty
    plain.sealed_request = seal_message(sealer, request, _request_purpose(request))
    return plain


def open_request(opener: Opener, request: Any, now_s: float | None = None) -> Any:
    """The request a sealed service request carries (its ``sealed_request`` opened); :class:`SealError`."""
    if not request.sealed_request.ciphertext:
        raise SealError("unsealed", "this master has a network key: requests must be sealed with it")
    inner = open_message(opener, request.sealed_request, type(request), now_s, _request_purpose(request))
    if inner.sealed_request.ciphertext:
        raise SealError("malformed", "a sealed request inside a sealed request")
    return inner
