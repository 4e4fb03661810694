"""Approximate time synchronisation of colour and depth streams that never queues stale frames.

The camera node must keep up with 30 Hz input: it only ever processes the NEWEST colour/depth
pair whose stamps differ by at most ``slop_s``; anything older is dropped and counted. This is a
plain class (no rclpy) so the policy is unit-tested directly.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar

T = TypeVar("T")
U = TypeVar("U")


@dataclass
class SyncStats:
    """Counters of what the synchroniser did with its input."""

    pairs: int = 0
    dropped_color: int = 0
    dropped_depth: int = 0
    rejected_out_of_order: int = 0


class StampSynchronizer(Generic[T, U]):
    """Pairs colour and depth items by stamp (seconds), newest first, within ``slop_s``."""

    def __init__(self, slop_s: float = 0.02, buffer_size: int = 16) -> None:
        if not slop_s >= 0:
            raise ValueError(f"slop_s must be >= 0 seconds, got {slop_s!r}")
        if buffer_size < 1:
            raise ValueError(f"buffer_size must be >= 1, got {buffer_size!r}")
        self.slop_s = float(slop_s)
        self._color: deque[tuple[float, T]] = deque(maxlen=buffer_size)
        self._depth: deque[tuple[float, U]] = deque(maxlen=buffer_size)
        self._last_paired_s = float("-inf")
        self.stats = SyncStats()

    def add_color(self, stamp_s: float, item: T) -> tuple[float, T, U] | None:
        """Add a colour frame; return (stamp, colour, depth) when it completes a pair."""
        if not self._accept(stamp_s):
            return None
        if len(self._color) == self._color.maxlen:
            self.stats.dropped_color += 1
        self._color.append((stamp_s, item))
        return self._match()

    def add_depth(self, stamp_s: float, item: U) -> tuple[float, T, U] | None:
        """Add a depth frame; return (stamp, colour, depth) when it completes a pair."""
        if not self._accept(stamp_s):
            return None
        if len(self._depth) == self._depth.maxlen:
            self.stats.dropped_depth += 1
        self._depth.append((stamp_s, item))
        return self._match()

    def _accept(self, stamp_s: float) -> bool:
        if not stamp_s > self._last_paired_s:
            self.stats.rejected_out_of_order += 1
            return False
        return True

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
