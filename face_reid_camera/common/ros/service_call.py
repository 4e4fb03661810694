"""One blocking service call for the command-line tools: wait for the service, call it, wait for the reply."""

from __future__ import annotations

import time
from typing import Any

__all__ = ["call_service"]


def call_service(node: Any, srv_type: Any, name: str, request: Any, timeout_s: float, hint: str = "") -> Any:
    """The reply of service ``name``; TimeoutError (naming ``hint``, what to check) when it is not offered or
    does not answer within ``timeout_s`` in all."""
    import rclpy

    client = node.create_client(srv_type, name)
    deadline = time.monotonic() + timeout_s
    while not client.service_is_ready():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no service {name} within {timeout_s:g} s" + (f" ({hint})" if hint else ""))
        rclpy.spin_once(node, timeout_sec=0.1)
    future = client.call_async(request)
    while not future.done():
        if time.monotonic() > deadline:
            raise TimeoutError(f"{name} did not answer within {timeout_s:g} s")
        rclpy.spin_once(node, timeout_sec=0.1)
    return future.result()
