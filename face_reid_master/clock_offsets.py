"""Each camera's clock against the master's: the median of (receive time - capture stamp - the camera's own
processing time) over its last frames. Large values mean a camera clock behind the master's (or a slow
network), negative ones a clock ahead; either way frames get refused as stale / future or tracked at the
wrong time, so the master warns. Pure Python: no rclpy.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

__all__ = ["ClockOffsets"]


@dataclass
class ClockOffsets:
    """Rolling offsets per camera; ``window``: frames per camera (>= 1); ``max_cameras``: cameras remembered,
    the least recently heard forgotten first (hostile ids cannot grow it)."""

    window: int = 50
    max_cameras: int = 1024
    _seen: dict[str, deque[float]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if self.window < 1:
            raise ValueError(f"window must be >= 1, got {self.window}")
        if self.max_cameras < 1:
            raise ValueError(f"max_cameras must be >= 1, got {self.max_cameras}")

    def observe(self, camera_id: str, stamp_s: float, received_s: float, processing_s: float = 0.0) -> None:
        """One frame of ``camera_id`` captured at ``stamp_s`` (its clock), received at ``received_s`` (ours)."""
        processing = processing_s if math.isfinite(processing_s) and 0.0 <= processing_s < 60.0 else 0.0
        offset = received_s - stamp_s - processing
        if not math.isfinite(offset):
            return
        key = camera_id[:256]
        values = self._seen.pop(key, None)
        if values is None:
            values = deque(maxlen=self.window)
        values.append(offset)
        self._seen[key] = values  # most recently heard last
        while len(self._seen) > self.max_cameras:
            del self._seen[next(iter(self._seen))]

    def offset_s(self, camera_id: str) -> float:
        """The camera's median offset (s; NaN: never heard)."""
        values = self._seen.get(camera_id[:256])
        return float(np.median(np.fromiter(values, float))) if values else math.nan

    def beyond(self, limit_s: float) -> dict[str, float]:
        """Cameras whose median offset is beyond ±``limit_s``, with it (s), largest first."""
        out = {cam: self.offset_s(cam) for cam in self._seen}
        return dict(sorted(((c, o) for c, o in out.items() if abs(o) > limit_s), key=lambda co: -abs(co[1])))
