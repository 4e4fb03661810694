"""Sealed service requests and replies (face_reid_camera.common.ros.sealed): a request is for one node and one
service; a reply is for one request of one node, so neither a captured request on another node nor a rogue's or
an old reply for a new request is taken."""

from __future__ import annotations

import time

import pytest

from face_reid_camera.common.ros.sealed import addressed, reply_is_sealed, reply_purpose, unaddressed
from face_reid_camera.common.sealing import KEY_BYTES, Opener, Sealer, SealError

KEY = bytes(range(KEY_BYTES))
OTHER = bytes(reversed(range(KEY_BYTES)))
CAM, MASTER = "/cam1/face_reid_camera", "/face_reid_master"


def _code(call, *args) -> str:  # type: ignore[no-untyped-def]
    with pytest.raises(SealError) as info:
        call(*args)
    return info.value.code


def test_a_request_names_its_node_and_another_node_refuses_it_saying_so() -> None:
    payload = addressed(CAM, b"\x00\x01\nrequest bytes")
    assert unaddressed(CAM, payload) == b"\x00\x01\nrequest bytes"
    with pytest.raises(SealError) as info:
        unaddressed(MASTER, payload)
    assert info.value.code == "misaddressed" and f"sealed for '{CAM}', not for this node ({MASTER})" in str(info.value)
    assert _code(unaddressed, MASTER, b"no node named") == "misaddressed"
    assert _code(unaddressed, "/cam1", payload) == "misaddressed"  # a prefix of the name is not the name
    with pytest.raises(ValueError):
        addressed("cam1/face_reid_camera", b"")  # not fully qualified


def test_a_reply_is_bound_to_its_service_node_and_request() -> None:
    base = reply_purpose("srv.ChangeState_Response", CAM, "operator", 5)
    others = {reply_purpose("srv.ListFaces_Response", CAM, "operator", 5),
              reply_purpose("srv.ChangeState_Response", MASTER, "operator", 5),
              reply_purpose("srv.ChangeState_Response", CAM, "operator2", 5),
              reply_purpose("srv.ChangeState_Response", CAM, "operator", 6)}
    assert base not in others and len(others) == 4
    sealed = Sealer(KEY, CAM).seal(b"done", base)
    assert Opener(KEY, "replies").open(sealed, purpose=base) == b"done"
    for purpose in others:
        assert _code(Opener(KEY, "replies").open, sealed, None, purpose) == "forged"


def test_only_a_key_holders_fresh_request_to_this_node_gets_a_sealed_reply() -> None:
    assert reply_is_sealed(None) and reply_is_sealed(SealError("stale", ""))
    for code in ("unsealed", "forged", "malformed", "misaddressed", "replayed"):
        assert not reply_is_sealed(SealError(code, ""))


def test_sealed_control_requests_and_replies_end_to_end() -> None:
    pytest.importorskip("rclpy")
    srv = pytest.importorskip("face_reid_msgs.srv")
    from face_reid_camera.common.ros.sealed import open_request, open_response, seal_request, seal_response

    operator = Sealer(KEY, "operator")
    request = seal_request(operator, srv.ChangeState.Request(transition="deactivate"), CAM)
    assert not request.transition and request.sealed_request.ciphertext  # on the wire only the sealed copy
    # captured on its way to the camera, sent to the master: refused, saying for whom it was sealed
    with pytest.raises(SealError) as info:
        open_request(Opener(KEY, "requests"), request, MASTER, time.time())
    assert info.value.code == "misaddressed" and CAM in str(info.value)
    cam_opener = Opener(KEY, "requests")
    assert open_request(cam_opener, request, CAM, time.time()).transition == "deactivate"
    assert _code(open_request, cam_opener, request, CAM, time.time()) == "replayed"
    assert _code(open_request, Opener(OTHER, "requests"), request, CAM, time.time()) == "forged"
    assert _code(open_request, cam_opener, srv.ChangeState.Request(transition="deactivate"), CAM) == "unsealed"
    # a ListFaces seal is not a ChangeState request
    faces = seal_request(operator, srv.ListFaces.Request(), CAM)
    assert _code(open_request, Opener(KEY, "requests"), srv.ChangeState.Request(
        sealed_request=faces.sealed_request), CAM, time.time()) == "forged"

    # the camera's reply: sealed for this request, fields cleared on the wire
    reply = seal_response(Sealer(KEY, CAM), srv.ChangeState.Response(success=True, message="deactivate: done",
                                                                      state="inactive"), CAM, request)
    assert not reply.message and not reply.state and not reply.success and reply.sealed_response.ciphertext
    opened = open_response(Opener(KEY, "replies"), reply, CAM, request, time.time())
    assert (opened.success, opened.message, opened.state) == (True, "deactivate: done", "inactive")
    # a rogue's plain reply, one sealed with another key, the same reply to a new request, the master's reply
    rogue = srv.ChangeState.Response(success=False, message="refused: nope", state="active")
    assert _code(open_response, Opener(KEY, "replies"), rogue, CAM, request) == "unsealed"
    foreign = seal_response(Sealer(OTHER, CAM), srv.ChangeState.Response(success=False), CAM, request)
    assert _code(open_response, Opener(KEY, "replies"), foreign, CAM, request) == "forged"
    again = seal_request(operator, srv.ChangeState.Request(transition="deactivate"), CAM)
    assert _code(open_response, Opener(KEY, "replies"), reply, CAM, again) == "forged"
    assert _code(open_response, Opener(KEY, "replies"), reply, MASTER, request) == "forged"
    # a list_faces reply carries the names only inside the seal
    listing = seal_response(Sealer(KEY, MASTER), srv.ListFaces.Response(face_ids=[3], names=["Alice"],
                                                                         num_features=[2], last_seen_s=[1.0]),
                            MASTER, faces)
    assert not listing.names and not listing.face_ids and not listing.last_seen_s
    assert list(open_response(Opener(KEY, "replies"), listing, MASTER, faces).names) == ["Alice"]
