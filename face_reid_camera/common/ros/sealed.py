"""ROS messages <-> sealed messages (face_reid_msgs/Sealed): serialize, seal; open, deserialize.

Used by the camera node (frames), the master (frames, admin requests) and admin clients. A sealed request names
the node it is for (a captured one is refused by every other node) and the service; a secured node's reply is
sealed for the request it answers (a server without the key can neither forge one nor replay an old one). The
cryptography is in :mod:`face_reid_camera.common.sealing`.
"""

from __future__ import annotations

from typing import Any

from face_reid_camera.common.sealing import Opener, Sealed, Sealer, SealError

__all__ = ["addressed", "open_message", "open_payload", "open_request", "open_response", "reply_is_sealed",
           "reply_purpose", "request_purpose", "seal_message", "seal_payload", "seal_request", "seal_response",
           "unaddressed", "unpack"]


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


def _type_name(msg: Any) -> str:
    return f"{type(msg).__module__}.{type(msg).__name__}"


def request_purpose(type_name: str) -> str:
    """A seal made for one service's requests (e.g. ``AddPerson_Request``) is not valid for another, nor as a
    frame."""
    return f"request:{type_name}"


def reply_purpose(type_name: str, node: str, sender_id: str, counter: int) -> str:
    """What a node's sealed reply is bound to: the service (its response type), the node that answers (fully
    qualified name) and the request (its sealer and counter), so that neither a reply of another node or service
    nor an old reply to another request opens as the answer to this one."""
    return f"reply:{type_name}:{node}:{sender_id}:{counter}"


def addressed(target: str, payload: bytes) -> bytes:
    """``payload`` (a serialized request) prefixed with the node it is meant for (its fully qualified name), all of
    which is then sealed: a request captured on its way to one node is refused by every other."""
    if not target.startswith("/") or "\n" in target:
        raise ValueError(f"a request's target is a fully qualified node name, got {target!r}")
    return target.encode("utf-8") + b"\n" + payload


def unaddressed(node: str, payload: bytes) -> bytes:
    """The serialized request in an opened ``payload`` when it names ``node``; :class:`SealError` ``misaddressed``
    (naming the node it was meant for, cut) when it names another."""
    target, sep, rest = payload.partition(b"\n")
    if not sep or target.decode("utf-8", "replace") != node:
        meant = target[:120].decode("utf-8", "replace") if sep else "no node"
        raise SealError("misaddressed", f"sealed for {meant!r}, not for this node ({node}): a request captured on its "
                                        "way to another node")
    return rest


def reply_is_sealed(error: SealError | None) -> bool:
    """Whether a secured node seals its reply to a request whose opening raised ``error`` (None: opened). Only a
    key holder's fresh request to this node gets a sealed reply (stale: its sender learns why). A reply to a
    replay is left plain: sealed, a rogue that relayed the operator's request to the node first could hand the
    operator a genuine "refused: replayed" while the node did what was asked."""
    return error is None or error.code == "stale"


def seal_request(sealer: Sealer, request: Any, target: str) -> Any:
    """A service request for node ``target`` (fully qualified name) whose ``sealed_request`` field carries the
    request itself, sealed for that service and that node (plain fields cleared: on the wire only the sealed copy
    says what is asked)."""
    from rclpy.serialization import serialize_message

    plain = type(request)()
    request.sealed_request = plain.sealed_request  # serialized with the field empty
    payload = addressed(target, serialize_message(request))
    plain.sealed_request = seal_payload(sealer, payload, request_purpose(_type_name(request)))
    return plain


def open_request(opener: Opener, request: Any, node: str, now_s: float | None = None) -> Any:
    """The request a sealed service request carries (its ``sealed_request`` opened), when it was sealed for
    ``node`` (this node's fully qualified name); :class:`SealError` (``unsealed``, ``misaddressed``, and those of
    :meth:`Opener.open`)."""
    from rclpy.serialization import deserialize_message

    if not request.sealed_request.ciphertext:
        raise SealError("unsealed", "this node has a network key: requests must be sealed with it")
    payload = unaddressed(node, open_payload(opener, request.sealed_request, now_s, request_purpose(
        _type_name(request))))
    try:
        inner = deserialize_message(payload, type(request))
    except Exception as exc:  # a key holder sealed something else
        raise SealError("malformed", f"the sealed payload is not a {type(request).__name__}: {exc}") from exc
    if inner.sealed_request.ciphertext:
        raise SealError("malformed", "a sealed request inside a sealed request")
    return inner


def _reply_purpose_for(response: Any, node: str, request: Any) -> str:
    sealed = request.sealed_request
    return reply_purpose(_type_name(response), node, str(sealed.sender_id), int(sealed.counter))


def seal_response(sealer: Sealer, response: Any, node: str, request: Any) -> Any:
    """A response of ``node`` whose ``sealed_response`` carries ``response`` itself, sealed for the (sealed)
    ``request`` it answers (plain fields cleared: only a key holder learns what happened)."""
    plain = type(response)()
    response.sealed_response = plain.sealed_response  # serialized with the field empty
    plain.sealed_response = seal_message(sealer, response, _reply_purpose_for(response, node, request))
    return plain


def open_response(opener: Opener, response: Any, node: str, request: Any, now_s: float | None = None) -> Any:
    """The response inside a reply to the sealed ``request`` sent to ``node``; :class:`SealError` when it must not
    be trusted (``unsealed``: a plain reply, e.g. from a server without the key; ``forged``: sealed for another
    node, service or request, or with another key)."""
    if not response.sealed_response.ciphertext:
        raise SealError("unsealed", "a plain reply: not from a node with the network key")
    inner = open_message(opener, response.sealed_response, type(response), now_s,
                         _reply_purpose_for(response, node, request))
    if inner.sealed_response.ciphertext:
        raise SealError("malformed", "a sealed reply inside a sealed reply")
    return inner
