"""Approximate time synchronisation of colour and depth streams that never queues stale frames.

The camera node must keep up with 30 Hz input: it only ever processes the NEWEST colour/depth
pair whose stamps differ by at most ``slop_s``; anything older is dropped and counted. Each image's stamp is
judged once, as it is received, by :class:`~face_reid_camera.common.stamp_admission.ImageStampGate` (the
receive clock's limits, the stream's pattern, the pairing's order: the rules and the constants are there); this
class pairs what the gate admits. Images are buffered in stamp order: one that came early does not push the
regular ones out, and pairs only once it is due (the gate's ``due_s``), so that early images cannot make the
regular ones out of order. A plain class (no rclpy) so the policy is unit-tested directly.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from face_reid_camera.common.stamp_admission import (  # noqa: F401  (the camera node and tests read them here)
    DROP_MEANINGS,
    DROP_REASONS,
    MAX_STAMP_FUTURE_S,
    PATTERN_AHEAD_S,
    PATTERN_SLACK_S,
    PATTERN_WINDOW,
    RESET_BACKWARD_S,
    ImageStampGate,
)

T = TypeVar("T")
U = TypeVar("U")


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

    ``max_age_s`` (0 = no limit) drops stamps older than that on the receive clock; 0 also says the stamps need
    not follow the receive clock (a test's or a recording's stamps, fed at any rate): then only the future limit
    applies, no pattern. ``on_drop(reason, text)`` hears of every dropped stamp (the node logs and counts them).
    """

    def __init__(self, slop_s: float = 0.02, buffer_size: int = 16, max_age_s: float = 0.0,
                 on_drop: Callable[[str, str], object] | None = None) -> None:
        if not slop_s >= 0:
            raise ValueError(f"slop_s must be >= 0 seconds, got {slop_s!r}")
        if buffer_size < 1:
            raise ValueError(f"buffer_size must be >= 1, got {buffer_size!r}")
        self.gate = ImageStampGate(max_age_s)  # judges each image's stamp (ValueError on a bad max_age_s)
        self.slop_s = float(slop_s)
        self.max_age_s = self.gate.max_age_s
        self._on_drop = on_drop
        self._color: deque[tuple[float, T]] = deque(maxlen=buffer_size)  # in stamp order
        self._depth: deque[tuple[float, U]] = deque(maxlen=buffer_size)
        self.stats = SyncStats()

    def add_color(self, stamp_s: float, item: T, now_s: float) -> tuple[float, T, U] | None:
        """Add a colour frame received at ``now_s``; return (stamp, colour, depth) when it completes a pair."""
        if not self._accept("colour", stamp_s, now_s):
            return None
        self.stats.dropped_color += _insert(self._color, stamp_s, item)
        return self._match(now_s)

    def add_depth(self, stamp_s: float, item: U, now_s: float) -> tuple[float, T, U] | None:
        """Add a depth frame received at ``now_s``; return (stamp, colour, depth) when it completes a pair."""
        if not self._accept("depth", stamp_s, now_s):
            return None
        self.stats.dropped_depth += _insert(self._depth, stamp_s, item)
        return self._match(now_s)

    def reset(self) -> None:
        """Forget every buffered frame and stamp (counted in ``stats.resets``); the streams' patterns stay."""
        self._color.clear()
        self._depth.clear()
        self.gate.restart()
        self.stats.resets += 1

    def _accept(self, stream: str, stamp_s: float, now_s: float) -> bool:
        verdict = self.gate.admit(stream, stamp_s, now_s)
        if verdict.restart:
            self._color.clear()
            self._depth.clear()
            self.stats.resets += 1
        if verdict.accepted:
            return True
        self.stats.rejected[verdict.code] += 1
        if self._on_drop is not None:
            self._on_drop(verdict.code, f"{verdict.reason}: dropped")
        return False

    def _match(self, now_s: float) -> tuple[float, T, U] | None:
        best: tuple[float, int, int] | None = None
        color_due, depth_due = self.gate.due_s("colour", now_s), self.gate.due_s("depth", now_s)
        for ci, (cs, _) in enumerate(self._color):
            if cs > color_due:  # early for its stream: it waits until it is due (the buffer is in stamp order)
                break
            for di, (ds, _) in enumerate(self._depth):
                if ds > depth_due:
                    break
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
        self.gate.paired(color_stamp)
        self.stats.pairs += 1
        return color_stamp, color, depth


def _insert(buffer: deque[tuple[float, T]], stamp_s: float, item: T) -> int:
    """``item`` into ``buffer`` in stamp order (after equal stamps); the oldest goes when it is full. Returns
    the number of frames dropped for room (0 or 1)."""
    dropped = 0
    if len(buffer) == buffer.maxlen:
        buffer.popleft()
        dropped = 1
    buffer.insert(bisect.bisect_right(buffer, stamp_s, key=lambda entry: entry[0]), (stamp_s, item))
    return dropped
