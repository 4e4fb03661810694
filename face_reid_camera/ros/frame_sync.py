"""Approximate time synchronisation of colour and depth streams that never queues stale frames.

The camera node must keep up with 30 Hz input: it only ever processes the NEWEST colour/depth
pair whose stamps differ by at most ``slop_s``; anything older is dropped and counted. Stamps are
checked against the receive clock (``now_s``) first, so no single stamp can silence the camera: one far
in the future is dropped instead of becoming the pairing's "last stamp", one far behind is dropped, and
a stream jumping back by more than :data:`RESET_BACKWARD_S` (a bag loop, a clock jump) restarts the
pairing. This is a plain class (no rclpy) so the policy is unit-tested directly.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T")
U = TypeVar("U")

MAX_STAMP_FUTURE_S = 2.0
"""A stamp further than this ahead of the receive clock is dropped (``stamp_future``)."""
RESET_BACKWARD_S = 1.0
"""A stream whose stamp goes back by more than this restarts the pairing; smaller steps back are dropped."""

DROP_REASONS = ("stamp_future", "stamp_past", "stamp_out_of_order")
DROP_MEANINGS = {
    "stamp_future": f"stamped more than {MAX_STAMP_FUTURE_S:g} s after they were received",
    "stamp_past": "stamped longer than max_frame_age_s before they were received",
    "stamp_out_of_order": "stamped before a frame already paired",
}


@dataclass
class SyncStats:
    """Counters of what the synchroniser did with its input."""

    pairs: int = 0
    dropped_color: int = 0
    dropped_depth: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DROP_REASONS, 0))
    resets: int = 0


class StampSynchronizer(Generic[T, U]):
    """Pairs colour and depth items by stamp (seconds), newest first, within ``slop_s``.

    ``max_age_s`` (0 = no limit) drops stamps older than that on the receive clock; ``on_drop(reason, text)``
    hears of every dropped stamp (the node logs and counts them).
    """

    def __init__(self, slop_s: float = 0.02, buffer_size: int = 16, max_age_s: float = 0.0,
                 on_drop: Callable[[str, str], object] | None = None) -> None:
        if not slop_s >= 0:
            raise ValueError(f"slop_s must be >= 0 seconds, got {slop_s!r}")
        if buffer_size < 1:
            raise ValueError(f"buffer_size must be >= 1, got {buffer_size!r}")
        if not max_age_s >= 0:
            raise ValueError(f"max_age_s must be >= 0 seconds, got {max_age_s!r}")
        self.slop_s = float(slop_s)
        self.max_age_s = float(max_age_s)
        self._on_drop = on_drop
        self._color: deque[tuple[float, T]] = deque(maxlen=buffer_size)
        self._depth: deque[tuple[float, U]] = deque(maxlen=buffer_size)
        self._last_s = {"colour": float("-inf"), "depth": float("-inf")}  # newest accepted stamp per stream
        self._last_paired_s = float("-inf")
        self.stats = SyncStats()

    def add_color(self, stamp_s: float, item: T, now_s: float) -> tuple[float, T, U] | None:
        """Add a colour frame received at ``now_s``; return (stamp, colour, depth) when it completes a pair."""
        if not self._accept("colour", stamp_s, now_s):
            return None
        if len(self._color) == self._color.maxlen:
            self.stats.dropped_color += 1
        self._color.append((stamp_s, item))
        return self._match()

    def add_depth(self, stamp_s: float, item: U, now_s: float) -> tuple[float, T, U] | None:
        """Add a depth frame received at ``now_s``; return (stamp, colour, depth) when it completes a pair."""
        if not self._accept("depth", stamp_s, now_s):
            return None
        if len(self._depth) == self._depth.maxlen:
            self.stats.dropped_depth += 1
        self._depth.append((stamp_s, item))
        return self._match()

    def reset(self) -> None:
        """Forget every buffered frame and stamp (counted in ``stats.resets``)."""
        self._color.clear()
        self._depth.clear()
        self._last_s = dict.fromkeys(self._last_s, float("-inf"))
        self._last_paired_s = float("-inf")
        self.stats.resets += 1

    def _accept(self, stream: str, stamp_s: float, now_s: float) -> bool:
        ahead = stamp_s - now_s
        if not ahead <= MAX_STAMP_FUTURE_S:  # also NaN
            return self._drop("stamp_future", f"{stream} stamp {ahead:.3f} s ahead of the clock "
                                              f"(> {MAX_STAMP_FUTURE_S:g} s)")
        if self.max_age_s > 0 and -ahead > self.max_age_s:
            return self._drop("stamp_past", f"{stream} stamp {-ahead:.3f} s old (> max_frame_age_s "
                                            f"{self.max_age_s:g})")
        if stamp_s < self._last_s[stream] - RESET_BACKWARD_S:
            self.reset()
        elif stamp_s < self._last_s[stream] or stamp_s <= self._last_paired_s:
            return self._drop("stamp_out_of_order", f"{stream} stamp {stamp_s:.6f} s is before the last paired "
                                                    f"{self._last_paired_s:.6f} s or its stream's last")
        self._last_s[stream] = stamp_s
        return True

    def _drop(self, reason: str, text: str) -> bool:
        self.stats.rejected[reason] += 1
        if self._on_drop is not None:
            self._on_drop(reason, f"{text}: dropped")
        return False

    def _match(self) -> tuple[float, T, U] | None:
        best: tuple[float, int, int] | None = None
        for ci, (cs, _) in enumerate(self._color):
            for di, (ds, _) in enumerate(self._depth):
                gap = abs(cs - ds)
                if gap <= self.slop_s and (best is None or max(cs, ds) > best[0]):
                    best = (max(cs, ds), ci, di)
        if best is None:
            return None
        _, ci, di = best
        color_stamp, color = self._color[ci]
        _, depth = self._depth[di]
        # Everything at or before the chosen pair is now stale: drop it (never queue).
        self.stats.dropped_color += ci
        self.stats.dropped_depth += di
        for _ in range(ci + 1):
            self._color.popleft()
        for _ in range(di + 1):
            self._depth.popleft()
        self._last_paired_s = color_stamp
        self.stats.pairs += 1
        return color_stamp, color, depth
