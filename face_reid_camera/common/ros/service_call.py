"""One blocking service call for the command-line tools: wait for the service, call it, wait for the reply (for a
sealed call, for the reply that opens with the network key)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

__all__ = ["call_service"]


def call_service(node: Any, srv_type: Any, name: str, request: Any, timeout_s: float, hint: str = "",
                 accept: Callable[[Any], Any] | None = None) -> Any:
    """The reply of service ``name``; TimeoutError (naming ``hint``, what to check) when it is not offered or
    does not answer within ``timeout_s`` in all.

    ``accept(reply)``: what to return for a reply, or None to pass it over and wait on for another reply to the
    same request until the timeout (a server without the key on the same name may answer first: rclpy hands the
    first reply to the call, so the call is put back in the client's pending requests for the genuine one).
    """
    import rclpy
    from rclpy.task import Future

    client = node.create_client(srv_type, name)
    deadline = time.monotonic() + timeout_s
    while not client.service_is_ready():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no service {name} within {timeout_s:g} s" + (f" ({hint})" if hint else ""))
        rclpy.spin_once(node, timeout_sec=0.1)
    future = client.call_async(request)
    sequence = next(seq for seq, pending in client._pending_requests.items() if pending is future)
    passed_over = 0
    while True:
        while not future.done():
            if time.monotonic() > deadline:
                raise TimeoutError(f"{name} did not answer within {timeout_s:g} s" + (
                    f" (only {passed_over} unauthenticated repl{'y' if passed_over == 1 else 'ies'}, from a server "
                    "without the key)" if passed_over else ""))
            rclpy.spin_once(node, timeout_sec=0.1)
        reply = future.result()
        taken = reply if accept is None else accept(reply)
        if taken is not None:
            return taken
        passed_over += 1
        # rclpy's private table of pending calls (stable since Humble): the next reply to this request completes
        # the new future; spin_once above takes replies one at a time, so none is missed in between
        future = Future()
        with client._lock:
            client._pending_requests[sequence] = future
        future.add_done_callback(client.remove_pending_request)
