"""When the master node runs a cycle, an identity step and a publish: the node's timing, without ROS.

A camera message starts a cycle no sooner than ``min_cycle_period_s`` after the last one began (messages
queue meanwhile); a cycle applies at most what :class:`~face_reid_master.intake.CycleBudget` allows; one
identity step follows at most every ``identity_period_s``; the tracks are published at most
``max_publish_rate_hz`` (a token bucket with bursts of 2, so that a camera's jitter around the cap's period
does not delay every other message; 0 = every cycle), a capped cycle's state being published when a token is
back. Clocks are passed in: ``mono`` is a monotonic clock (s), ``now`` the node's clock (s).
"""

from __future__ import annotations

import math

from face_reid_master.intake import CycleBudget

__all__ = ["CycleSchedule"]

_BURST = 2.0  # publishes the rate cap lets through back to back


class CycleSchedule:
    """The master node's cycle, identity and publish timing (see the module doc)."""

    def __init__(self, min_cycle_period_s: float = 0.0, identity_period_s: float = 0.0,
                 max_publish_rate_hz: float = 0.0, budget_ms: float = 40.0) -> None:
        for name, value in (("min_cycle_period_s", min_cycle_period_s), ("identity_period_s", identity_period_s),
                            ("max_publish_rate_hz", max_publish_rate_hz)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        self.min_cycle_period_s = min_cycle_period_s
        self.identity_period_s = identity_period_s
        self.publish_interval_s = 1.0 / max_publish_rate_hz if max_publish_rate_hz > 0 else 0.0
        self.budget = CycleBudget(budget_ms=budget_ms)
        self.cycle_began = -math.inf  # mono when the last cycle began
        self.identity_done = -math.inf  # mono of the last identity step
        self.unpublished_stamp: float | None = None  # newest frame stamp applied but not published (rate cap)
        self._tokens = _BURST
        self._tokens_counted = -math.inf  # now when the tokens were last counted

    def wait_s(self, mono: float) -> float:
        """How long a camera message must wait before its cycle may begin (s, <= min_cycle_period_s)."""
        return max(0.0, self.cycle_began + self.min_cycle_period_s - mono)

    def begin_cycle(self, mono: float) -> int:
        """A cycle begins: the most frames it may apply."""
        self.cycle_began = mono
        return self.budget.frames()

    def identity_due(self, mono: float) -> bool:
        """Whether a cycle ending now runs the identity step."""
        return mono - self.identity_done >= self.identity_period_s

    def identity_ran(self, mono: float) -> None:
        self.identity_done = mono

    def cycle_cost(self, frames: int, elapsed_ms: float, once_ms: float) -> None:
        """A cycle applied ``frames`` in ``elapsed_ms``, ``once_ms`` of it paid once (the identity step)."""
        self.budget.spent(frames, elapsed_ms, once_ms)

    def may_publish(self, now: float, stamp: float) -> bool:
        """Whether the state after a cycle that applied frames up to ``stamp`` is published now (else it is kept
        for :meth:`due_publish`)."""
        if self._take_token(now):
            return True
        self.unpublished_stamp = stamp
        return False

    def due_publish(self, now: float) -> float | None:
        """The stamp of a capped cycle's state when it may be published now (the rate cap's timer)."""
        if self.unpublished_stamp is not None and self._take_token(now):
            return self.unpublished_stamp
        return None

    def published(self) -> None:
        self.unpublished_stamp = None

    def _take_token(self, now: float) -> bool:
        if not self.publish_interval_s:
            return True
        elapsed = max(0.0, now - self._tokens_counted)
        self._tokens = min(_BURST, self._tokens + elapsed / self.publish_interval_s)
        self._tokens_counted = now  # counted from here on (also when this cycle does not publish)
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False
