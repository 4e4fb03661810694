"""The header stamps of /tracks_named: never ahead of the master's clock, never backwards.

A camera whose clock runs ahead (within ``max_stamp_future_s``) would otherwise put its future stamps on the
output, and the master's timer messages (stamped by the master) would then step back behind them: a consumer
that orders or extrapolates by stamp is misled. Pure Python, no rclpy.
"""

from __future__ import annotations

import math

__all__ = ["OutputStamps"]


class OutputStamps:
    """Each output stamp is ``min(tracker's time, master's now)``, raised to the previous stamp if it is behind
    it: non-decreasing. Only the master's own clock going back (a clock step, simulated time restarted) lowers a
    stamp, to that clock: never being ahead of it wins over monotonicity."""

    def __init__(self) -> None:
        self._last = -math.inf

    def next(self, tracker_s: float, now_s: float) -> float:
        """The stamp of the next message: the tracker's time ``tracker_s`` (the newest frame applied, or the
        time it was advanced to; not finite = none yet, then ``now_s``) bounded by the master's clock ``now_s``."""
        stamp = min(tracker_s, now_s) if math.isfinite(tracker_s) else now_s
        stamp = min(max(stamp, self._last), now_s)
        self._last = stamp
        return stamp

    def reset(self) -> None:
        """Forget the previous stamp (a new activation of the master)."""
        self._last = -math.inf
