"""Steps of the host's wall clock, told apart from its monotonic clock: what a node says on /diagnostics.

A wall clock that steps (by hand, a first NTP sync, a glitch) moves every stamp, seal counter and deadline the
node derives from it; the monotonic clock does not step. :class:`ClockStepDetector` follows ``wall - mono``:
a change beyond ``threshold_s`` is a step (counted, in either direction), and the node is stepped (an ERROR)
until the offset comes back (the step was corrected: that return is counted as a step too) or has held for
``settle_s`` (the new clock is taken as right). Slow corrections (NTP slewing) move the offset within the
threshold and are followed. Pure Python, no rclpy: the nodes feed it ``time.time()`` and ``time.monotonic()``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ClockStepDetector"]

STEP_THRESHOLD_S = 1.0  # a change of wall - monotonic beyond this is a step (NTP slews far less per call)
SETTLE_S = 30.0  # a step that holds this long is the clock from then on (the ERROR ends)


@dataclass
class ClockStepDetector:
    """Follows wall - monotonic and says when the wall clock stepped (see the module doc)."""

    threshold_s: float = STEP_THRESHOLD_S
    settle_s: float = SETTLE_S
    steps: int = 0  # steps seen, either direction (a step and its correction are two)
    last_step_s: float = 0.0  # the size of the last step (s; + the wall clock jumped ahead)
    refused_during_steps: int = 0  # inputs the node refused while its clock was stepped (count_refused)
    _refused_total: int | None = None  # the node's refused total at the last count_refused
    _stepped_since_count: bool = False  # stepped at some reading since the last count_refused
    _baseline: float | None = None  # wall - mono of the trusted clock
    _stepped_at: float | None = None  # mono when the current step began (None: not stepped)
    _step_offset: float = 0.0  # wall - mono during the current step

    def __post_init__(self) -> None:
        if not (self.threshold_s > 0 and self.settle_s > 0):
            raise ValueError(f"threshold_s and settle_s must be > 0, got {self.threshold_s}, {self.settle_s}")

    def update(self, wall_s: float, mono_s: float) -> bool:
        """One reading of both clocks; True when a new step was seen with it."""
        offset = wall_s - mono_s
        if not math.isfinite(offset):
            return False
        new = self._update(offset, mono_s)
        self._stepped_since_count |= new or self.stepped
        return new

    def observe(self, wall_s: float, mono_s: float, refused_total: int) -> list[str]:
        """A node's diagnostics step: one reading of both clocks and the node's refused-input total; the errors
        to report (the step while it lasts)."""
        self.update(wall_s, mono_s)
        self.count_refused(refused_total)
        return [self.describe()] if self.stepped else []

    def values(self) -> dict[str, object]:
        """The fields of a node's /diagnostics about its clock."""
        return {"clock_stepped": self.stepped, "clock_step_s": round(self.offset_s, 3), "clock_steps": self.steps,
                "clock_last_step_s": round(self.last_step_s, 3),
                "rejected_during_clock_steps": self.refused_during_steps}

    def count_refused(self, refused_total: int) -> None:
        """The node's total of refused inputs now: those refused since the last call are added to
        ``refused_during_steps`` when the clock was stepped meanwhile (the step's effect, counted)."""
        if self._refused_total is not None and self._stepped_since_count:
            self.refused_during_steps += max(0, refused_total - self._refused_total)
        self._refused_total = refused_total
        self._stepped_since_count = self.stepped

    def _update(self, offset: float, mono_s: float) -> bool:
        if self._baseline is None:
            self._baseline = offset
            return False
        if abs(offset - self._baseline) <= self.threshold_s:  # on the trusted clock (again)
            returned = self._stepped_at is not None
            if returned:
                self._count(offset - self._step_offset)
            self._stepped_at = None
            self._baseline = offset  # follows slewing
            return returned
        if self._stepped_at is None or abs(offset - self._step_offset) > self.threshold_s:  # a (further) step
            self._count(offset - (self._baseline if self._stepped_at is None else self._step_offset))
            self._stepped_at, self._step_offset = mono_s, offset
            return True
        self._step_offset = offset
        if mono_s - self._stepped_at >= self.settle_s:  # it held: the new clock is the clock
            self._baseline, self._stepped_at = offset, None
        return False

    @property
    def stepped(self) -> bool:
        """Whether the wall clock is off the trusted one now (a step not corrected and not yet settled)."""
        return self._stepped_at is not None

    @property
    def offset_s(self) -> float:
        """How far the wall clock is from the trusted one now (s; + ahead; 0 when not stepped)."""
        return self._step_offset - self._baseline if self._stepped_at is not None and self._baseline is not None \
            else 0.0

    def describe(self) -> str:
        """The ERROR of a stepped clock, in words (empty when not stepped)."""
        if not self.stepped:
            return ""
        return (f"this host's clock stepped {self.offset_s:+.1f} s ({self.steps} step(s) so far): stamps, seals and "
                f"deadlines follow it; fix the clock (chrony / NTP), or it is taken as right after "
                f"{self.settle_s:g} s")

    def _count(self, size_s: float) -> None:
        self.steps += 1
        self.last_step_s = size_s
