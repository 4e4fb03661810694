"""Frames waiting for the master's next cycle: stamp order, a per-cycle budget, fair oldest-first dropping.

The master node drains every camera subscription once per cycle into a :class:`FrameIntake`, applies what
:meth:`FrameIntake.take` returns in stamp order and publishes once. When more arrived than one cycle may
apply (an overloaded host), the oldest frames of the cameras with the most waiting are dropped and counted,
so no camera is starved and no backlog (latency) builds up. Pure Python: no rclpy.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Generic, TypeVar

__all__ = ["CycleBudget", "FrameIntake", "PendingFrame"]

T = TypeVar("T")
_UNLIMITED = 1 << 30


@dataclass(frozen=True)
class PendingFrame(Generic[T]):
    """One received frame: its camera, its stamp (s) and the payload (the message)."""

    camera_id: str
    stamp_s: float
    payload: T


@dataclass
class FrameIntake(Generic[T]):
    """Frames received since the last cycle; see the module docstring."""

    _waiting: list[PendingFrame[T]] = field(default_factory=list)
    dropped: int = 0  # frames dropped for overload since start

    def add(self, frame: PendingFrame[T]) -> None:
        self._waiting.append(frame)

    def clear(self) -> None:
        """Forget what waits (not counted as dropped: e.g. the node is being deactivated)."""
        self._waiting = []

    def __len__(self) -> int:
        return len(self._waiting)

    def take(self, max_frames: int) -> tuple[list[PendingFrame[T]], int]:
        """Everything waiting, at most ``max_frames`` (>= 1), in stamp order, and how many were dropped.

        Over the limit, the oldest frame of the camera with the most frames waiting is dropped first, until
        the rest fits. Frames whose stamp is not a finite number sort last (the core rejects them).
        """
        if max_frames < 1:
            raise ValueError(f"max_frames must be >= 1, got {max_frames}")
        frames, self._waiting = self._waiting, []
        excess = len(frames) - max_frames
        if excess > 0:
            frames = _drop_fairly(frames, excess)
            self.dropped += excess
        frames.sort(key=lambda f: (not math.isfinite(f.stamp_s), f.stamp_s if math.isfinite(f.stamp_s) else 0.0))
        return frames, max(0, excess)


def _drop_fairly(frames: list[PendingFrame[T]], excess: int) -> list[PendingFrame[T]]:
    """``frames`` without ``excess`` of them: each time the oldest of the camera with the most frames."""
    by_camera: dict[str, list[PendingFrame[T]]] = defaultdict(list)
    for f in frames:
        by_camera[f.camera_id].append(f)
    for queue in by_camera.values():  # oldest last, so pop() drops it
        queue.sort(key=lambda f: f.stamp_s if math.isfinite(f.stamp_s) else -math.inf, reverse=True)
    for _ in range(excess):
        fullest = max(by_camera.values(), key=len)
        fullest.pop()
    return [f for queue in by_camera.values() for f in queue]


@dataclass
class CycleBudget:
    """How many frames one cycle may apply: what ``budget_ms`` leaves after the cycle's own cost, over the
    running mean cost of a frame.

    A cycle costs its frames (tracking each) plus a part paid once however many frames it holds (the identity
    update); both are learnt apart, so a busy cycle is not refused frames it has time for.
    ``budget_ms``: the time one cycle may spend (ms, > 0); ``min_frames``: applied however slow frames are
    (>= 1); ``smoothing``: weight of the newest cost in the running means (0 < s <= 1).
    """

    budget_ms: float = 40.0
    min_frames: int = 4
    smoothing: float = 0.1
    mean_cost_ms: float = 0.0  # per frame
    mean_cycle_ms: float = 0.0  # per cycle, on top of its frames

    def __post_init__(self) -> None:
        if not (math.isfinite(self.budget_ms) and self.budget_ms > 0):
            raise ValueError(f"budget_ms must be a finite number > 0, got {self.budget_ms}")
        if self.min_frames < 1:
            raise ValueError(f"min_frames must be >= 1, got {self.min_frames}")
        if not (0.0 < self.smoothing <= 1.0):
            raise ValueError(f"smoothing must be in (0, 1], got {self.smoothing}")

    def frames(self) -> int:
        """The most frames the next cycle may apply."""
        if self.mean_cost_ms <= 0.0 and self.mean_cycle_ms <= 0.0:  # nothing measured yet: no limit
            return _UNLIMITED
        return max(self.min_frames, int((self.budget_ms - self.mean_cycle_ms) / max(self.mean_cost_ms, 1e-3)))

    def spent(self, frames: int, elapsed_ms: float, cycle_ms: float = 0.0) -> None:
        """Learn from a cycle that applied ``frames`` in ``elapsed_ms``, of which ``cycle_ms`` were paid once for
        the whole cycle."""
        if frames <= 0 or not math.isfinite(elapsed_ms) or elapsed_ms < 0:
            return
        cycle_ms = min(max(cycle_ms, 0.0), elapsed_ms) if math.isfinite(cycle_ms) else 0.0
        cost = (elapsed_ms - cycle_ms) / frames
        if self.mean_cost_ms <= 0 and self.mean_cycle_ms <= 0:  # the first measurement
            self.mean_cost_ms, self.mean_cycle_ms = cost, cycle_ms
            return
        w = self.smoothing
        self.mean_cost_ms = (1.0 - w) * self.mean_cost_ms + w * cost
        self.mean_cycle_ms = (1.0 - w) * self.mean_cycle_ms + w * cycle_ms
