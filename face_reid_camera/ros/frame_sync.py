"""Approximate time synchronisation of colour and depth streams that never queues stale frames.

The camera node must keep up with 30 Hz input: it only ever processes the NEWEST colour/depth
pair whose stamps differ by at most ``slop_s``; anything older is dropped and counted. Stamps are
checked against the receive clock (``now_s``) first, so no single stamp can silence the camera: one far
in the future is dropped, one far behind is dropped. Then against the stream's pattern: the median of
``stamp - now_s`` over its last :data:`PATTERN_WINDOW` images; an image more than
:data:`PATTERN_AHEAD_S` ahead of it or :data:`RESET_BACKWARD_S` behind it is dropped
(``stamp_out_of_pattern``), so that one forged stamp just under the future limit neither starves the
regular images nor restarts the pairing (a real change of the pattern, a clock step, moves the median
within half a window). Images are buffered in stamp order: one that came early does not push the
regular ones out, and pairs only once it is due (:data:`PATTERN_SLACK_S`), so that early images cannot make
the regular ones out of order (only images at or before the last pair are). The pattern applies with an age limit
(``max_age_s`` > 0, the camera's default): stamps on the receive clock. An image in pattern more
than :data:`RESET_BACKWARD_S` before the stream's newest (a bag loop, a clock jump back of both the
stamps and the receive clock) restarts the pairing. This is a plain class (no rclpy) so the policy is
unit-tested directly.
"""

from __future__ import annotations

import bisect
import math
import statistics
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T")
U = TypeVar("U")

MAX_STAMP_FUTURE_S = 2.0
"""A stamp further than this ahead of the receive clock is dropped (``stamp_future``)."""
RESET_BACKWARD_S = 1.0
"""A stream whose stamp goes back by more than this restarts the pairing; smaller steps back are dropped. A
stamp this far behind its stream's pattern is dropped (``stamp_out_of_pattern``)."""
PATTERN_AHEAD_S = 0.25
"""A stamp further than this ahead of its stream's pattern (stamp - receive time) is dropped: what one such
image can cost the regular ones is bounded by it."""
PATTERN_WINDOW = 15
"""Images (received within the absolute limits) whose ``stamp - now_s`` make a stream's pattern."""
PATTERN_SLACK_S = 0.05
"""An image ahead of its stream's pattern by more than this (but within PATTERN_AHEAD_S) waits to pair until
the receive clock makes it due: a forged pair stamped a little ahead cannot make the regular ones out of order."""
_PATTERN_MIN = 3  # the pattern is judged from this many images on

DROP_REASONS = ("stamp_future", "stamp_past", "stamp_out_of_order", "stamp_out_of_pattern")
DROP_MEANINGS = {
    "stamp_future": f"stamped more than {MAX_STAMP_FUTURE_S:g} s after they were received",
    "stamp_past": "stamped longer than max_frame_age_s before they were received",
    "stamp_out_of_order": "stamped before a frame already paired",
    "stamp_out_of_pattern": f"stamped more than {PATTERN_AHEAD_S:g} s ahead of (or {RESET_BACKWARD_S:g} s behind) "
                            "the stream's other images",
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
        if not max_age_s >= 0:
            raise ValueError(f"max_age_s must be >= 0 seconds, got {max_age_s!r}")
        self.slop_s = float(slop_s)
        self.max_age_s = float(max_age_s)
        self._on_drop = on_drop
        self._color: deque[tuple[float, T]] = deque(maxlen=buffer_size)  # in stamp order
        self._depth: deque[tuple[float, U]] = deque(maxlen=buffer_size)
        self._pattern: dict[str, deque[float]] = {s: deque(maxlen=PATTERN_WINDOW) for s in ("colour", "depth")}
        self._last_s = {"colour": float("-inf"), "depth": float("-inf")}  # newest accepted stamp per stream
        self._last_paired_s = float("-inf")
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
        pattern = self._pattern[stream]
        pattern.append(ahead)
        if self.max_age_s > 0 and len(pattern) >= _PATTERN_MIN:
            off = ahead - statistics.median(pattern)
            if off > PATTERN_AHEAD_S or off < -RESET_BACKWARD_S:
                return self._drop("stamp_out_of_pattern", f"{stream} stamp {off:+.3f} s off its stream's pattern "
                                                          f"(stamp - receive time of its last {len(pattern)} images)")
        if stamp_s < max(self._last_s[stream], self._last_paired_s) - RESET_BACKWARD_S:
            self.reset()
        elif stamp_s <= self._last_paired_s:
            return self._drop("stamp_out_of_order", f"{stream} stamp {stamp_s:.6f} s is at or before the last "
                                                    f"paired {self._last_paired_s:.6f} s")
        self._last_s[stream] = max(self._last_s[stream], stamp_s)
        return True

    def _drop(self, reason: str, text: str) -> bool:
        self.stats.rejected[reason] += 1
        if self._on_drop is not None:
            self._on_drop(reason, f"{text}: dropped")
        return False

    def _due_s(self, stream: str, now_s: float) -> float:
        """The newest stamp of ``stream`` that may pair at ``now_s``: its pattern's + PATTERN_SLACK_S (inf while
        the pattern is not known, or without an age limit)."""
        pattern = self._pattern[stream]
        if self.max_age_s == 0 or len(pattern) < _PATTERN_MIN:
            return math.inf
        return now_s + statistics.median(pattern) + PATTERN_SLACK_S

    def _match(self, now_s: float) -> tuple[float, T, U] | None:
        best: tuple[float, int, int] | None = None
        color_due, depth_due = self._due_s("colour", now_s), self._due_s("depth", now_s)
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
        self._last_paired_s = color_stamp
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
