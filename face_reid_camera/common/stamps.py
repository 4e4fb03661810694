"""Conversions between seconds (float) and ROS ``builtin_interfaces/Time`` fields: the one place that does it."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["seconds_to_stamp", "set_stamp", "stamp_to_seconds"]


def seconds_to_stamp(stamp_s: float) -> tuple[int, int]:
    """(sec, nanosec) for ``stamp_s`` seconds, nanosec in [0, 1e9)."""
    sec = math.floor(stamp_s)
    nanosec = round((stamp_s - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return int(sec), int(nanosec)


def stamp_to_seconds(stamp: Any) -> float:
    """Seconds of anything with ``sec`` and ``nanosec`` (a Time message, a header stamp)."""
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def set_stamp(stamp: Any, stamp_s: float) -> Any:
    """Write ``stamp_s`` into a Time message's ``sec`` / ``nanosec`` in place; returns it."""
    stamp.sec, stamp.nanosec = seconds_to_stamp(stamp_s)
    return stamp
