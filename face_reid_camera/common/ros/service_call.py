"""One blocking service call for the command-line tools: wait for the service, call it, wait for the reply (for a
sealed call, for the reply that opens with the network key)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["REPLY_AGE_S", "RESEND_S", "SealedCaller", "call_service"]

RESEND_S = 1.0  # after a passed-over reply, the request is sent again this often (s) until a reply is taken
REPLY_AGE_S = 30.0  # a sealed reply stamped further than this from this host's clock is not trusted (s)


def call_service(node: Any, srv_type: Any, name: str, request: Any, timeout_s: float, hint: str = "",
                 accept: Callable[[Any], Any] | None = None) -> Any:
    """The reply of service ``name``; TimeoutError (naming ``hint``, what to check) when it is not offered or
    does not answer within ``timeout_s`` in all.

    ``accept(reply)``: what to return for a reply, or None to pass it over and wait on for another until the
    timeout. Another server on the same name (one without the key) may answer first, and rclpy hands only the
    first reply to a call: the call is put back in the client's pending calls for the genuine reply, and, while
    only passed-over replies came, the same request is sent again every RESEND_S (for the genuine server when it
    was not yet discovered as the request went out; a secured node refuses a copy it already had as a replay, so
    what was asked is done at most once).
    """
    import rclpy

    client = node.create_client(srv_type, name)
    deadline = time.monotonic() + timeout_s
    while not client.service_is_ready():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no service {name} within {timeout_s:g} s" + (f" ({hint})" if hint else ""))
        rclpy.spin_once(node, timeout_sec=0.1)
    pending = [_send(client, request)]
    passed_over, sent_s = 0, time.monotonic()
    while True:
        for k, (sequence, future) in enumerate(pending):
            if not future.done():
                continue
            reply = future.result()
            taken = reply if accept is None else accept(reply)
            if taken is not None:
                return taken
            passed_over += 1
            pending[k] = (sequence, _wait_again(client, sequence))
        if passed_over and time.monotonic() - sent_s > RESEND_S:
            pending.append(_send(client, request))
            sent_s = time.monotonic()
        if time.monotonic() > deadline:
            raise TimeoutError(f"{name} did not answer within {timeout_s:g} s" + (
                f" (only {passed_over} unauthenticated repl{'y' if passed_over == 1 else 'ies'}: from a server "
                "without the key, or the node refusing the repeated request)" if passed_over else ""))
        rclpy.spin_once(node, timeout_sec=0.1)


def _send(client: Any, request: Any) -> tuple[int, Any]:
    """``request`` sent: its sequence number and future."""
    future = client.call_async(request)
    with client._lock:  # rclpy's private table of pending calls (the same since Humble)
        return next(seq for seq, waiting in client._pending_requests.items() if waiting is future), future


def _wait_again(client: Any, sequence: int) -> Any:
    """A new future for the next reply to call ``sequence`` (spin_once takes replies one at a time and this runs
    between them, so none is missed)."""
    from rclpy.task import Future

    future: Any = Future()
    with client._lock:
        client._pending_requests[sequence] = future
    future.add_done_callback(client.remove_pending_request)
    return future


@dataclass
class SealedCaller:
    """Calls services of secured nodes for one tool: each request sealed with the network ``key`` for its node,
    only that node's reply sealed for the request taken (a plain or forged one, e.g. from a server without the
    key on the same name, is reported once on stderr and passed over: the call waits on for the genuine one;
    :attr:`passed_over` counts them for the last call)."""

    node: Any
    key: bytes
    prog: str
    hint: str = ""

    def __post_init__(self) -> None:
        from face_reid_camera.common.sealing import Opener, Sealer

        self._sealer = Sealer(self.key, f"{self.prog}-{time.time_ns() % 10**9}")
        self._opener = Opener(self.key, "replies", REPLY_AGE_S)
        self.passed_over = 0

    def call(self, srv_type: Any, target: str, service: str, request: Any, timeout_s: float) -> Any:
        """The reply (opened) of ``target``'s service ``service`` (e.g. ``change_state_sealed``) to ``request``;
        TimeoutError as :func:`call_service`."""
        from face_reid_camera.common.ros.sealed import open_response, seal_request
        from face_reid_camera.common.sealing import SealError

        name = f"{target}/{service}"
        sealed = seal_request(self._sealer, request, target)
        self.passed_over = 0

        def genuine(reply: Any) -> Any:
            try:
                return open_response(self._opener, reply, target, sealed)
            except SealError as exc:
                if not self.passed_over:  # once: a rogue server answers every copy
                    print(f"{self.prog}: {name}: unauthenticated reply from a server without the key ({exc}): "
                          "ignored, waiting for the node's own", file=sys.stderr, flush=True)
                self.passed_over += 1
                return None

        return call_service(self.node, srv_type, name, sealed, timeout_s, self.hint, genuine)
