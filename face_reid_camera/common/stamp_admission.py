"""A frame's stamps judged once, at the edge: every rule on time and the clocks those rules compare against.

Two gates, one per side, each called once per input (pure Python, no rclpy; the callers count and log):

- :class:`ImageStampGate` (the camera, each colour / depth image as it is received): a stamp further than
  :data:`MAX_STAMP_FUTURE_S` ahead of the receive clock or (with an age limit) older than ``max_age_s`` is
  dropped; then against the stream's pattern, the median of ``stamp - now`` over its last :data:`PATTERN_WINDOW`
  images (more than :data:`PATTERN_AHEAD_S` ahead of it, or :data:`RESET_BACKWARD_S` behind it: dropped), so that
  one forged stamp just under the future limit neither starves the regular images nor restarts the pairing; then
  against the pairing's order (at or before the last pair: dropped; more than RESET_BACKWARD_S before the stream's
  newest: the pairing restarts). An admitted frame has a deadline (``max_age_s`` after its stamp) that the
  camera's worker honours (:meth:`ImageStampGate.expired`): a pair that waited too long is not processed.
- :class:`FrameStampGate` (the master, each received camera frame before the core uses it): against the caller's
  clock (too old, too far ahead: refused; a little ahead: applied at the caller's clock; the caller's clock gone
  back: tracking starts afresh), then against the tracker clock (:class:`StampClock`, the newest applied stamp:
  older than ``max_detection_delay_s`` or further than ``max_future_stamp_s`` ahead: refused, until a run of
  ``clock_resync_frames`` such stamps re-bases it). The tracker is given that verdict and does not judge again.

The seal's counter window (:class:`~face_reid_camera.common.sealing.Opener` ``max_age_s``) is not a stamp rule: it
bounds the replay cache of the sealed channel and is judged there.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass

__all__ = [
    "DROP_MEANINGS", "DROP_REASONS", "MAX_STAMP_FUTURE_S", "PATTERN_AHEAD_S", "PATTERN_SLACK_S", "PATTERN_WINDOW",
    "RESET_BACKWARD_S", "ClockVerdict", "FrameStampGate", "FrameVerdict", "ImageStampGate", "ImageVerdict",
    "StampClock", "finite_stamp",
]

EPS_S = 1e-9  # tolerance on the tracker clock's comparisons (tracking.lifecycle.EPS_S)

# ---------------------------------------------------------------------------------------------- camera images
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
STREAMS = ("colour", "depth")


@dataclass(frozen=True, slots=True)
class ImageVerdict:
    """The verdict on one image's stamp: ``code`` a DROP_REASONS entry ('' = accepted), ``reason`` in words,
    ``restart``: accepted, but the pairing must restart first (the stream went back: a bag loop, a clock jump)."""

    code: str = ""
    reason: str = ""
    restart: bool = False

    @property
    def accepted(self) -> bool:
        return not self.code


_ACCEPTED = ImageVerdict()
_RESTART = ImageVerdict(restart=True)


class ImageStampGate:
    """The camera's rules on image stamps (see the module doc), and the receive clock's patterns they use.

    ``max_age_s`` (0 = no limit) drops stamps older than that on the receive clock; 0 also says the stamps need
    not follow the receive clock (a test's or a recording's stamps, fed at any rate): then only the future limit
    and the order apply, no pattern."""

    def __init__(self, max_age_s: float = 0.0) -> None:
        if not max_age_s >= 0:
            raise ValueError(f"max_age_s must be >= 0 seconds, got {max_age_s!r}")
        self.max_age_s = float(max_age_s)
        self._pattern: dict[str, deque[float]] = {s: deque(maxlen=PATTERN_WINDOW) for s in STREAMS}
        self._last_s = dict.fromkeys(STREAMS, -math.inf)  # newest accepted stamp per stream
        self._last_paired_s = -math.inf

    def admit(self, stream: str, stamp_s: float, now_s: float) -> ImageVerdict:
        """The verdict on an image of ``stream`` stamped ``stamp_s`` received at ``now_s`` (the one judgment)."""
        ahead = stamp_s - now_s
        if not ahead <= MAX_STAMP_FUTURE_S:  # also NaN
            return ImageVerdict("stamp_future", f"{stream} stamp {ahead:.3f} s ahead of the clock "
                                                f"(> {MAX_STAMP_FUTURE_S:g} s)")
        if self.max_age_s > 0 and -ahead > self.max_age_s:
            return ImageVerdict("stamp_past", f"{stream} stamp {-ahead:.3f} s old (> max_frame_age_s "
                                              f"{self.max_age_s:g})")
        pattern = self._pattern[stream]
        pattern.append(ahead)
        if self.max_age_s > 0 and len(pattern) >= _PATTERN_MIN:
            off = ahead - statistics.median(pattern)
            if off > PATTERN_AHEAD_S or off < -RESET_BACKWARD_S:
                return ImageVerdict("stamp_out_of_pattern", f"{stream} stamp {off:+.3f} s off its stream's pattern "
                                                            f"(stamp - receive time of its last {len(pattern)} images)")
        verdict = _ACCEPTED
        if stamp_s < max(self._last_s[stream], self._last_paired_s) - RESET_BACKWARD_S:
            self.restart()
            verdict = _RESTART
        elif stamp_s <= self._last_paired_s:
            return ImageVerdict("stamp_out_of_order", f"{stream} stamp {stamp_s:.6f} s is at or before the last "
                                                      f"paired {self._last_paired_s:.6f} s")
        self._last_s[stream] = max(self._last_s[stream], stamp_s)
        return verdict

    def restart(self) -> None:
        """Forget the streams' newest and the last paired stamp (the pairing restarts); the patterns stay."""
        self._last_s = dict.fromkeys(STREAMS, -math.inf)
        self._last_paired_s = -math.inf

    def paired(self, stamp_s: float) -> None:
        """A pair stamped ``stamp_s`` was made: images at or before it are out of order from now on."""
        self._last_paired_s = stamp_s

    def due_s(self, stream: str, now_s: float) -> float:
        """The newest stamp of ``stream`` that may pair at ``now_s``: its pattern's + PATTERN_SLACK_S (inf while
        the pattern is not known, or without an age limit)."""
        pattern = self._pattern[stream]
        if self.max_age_s == 0 or len(pattern) < _PATTERN_MIN:
            return math.inf
        return now_s + statistics.median(pattern) + PATTERN_SLACK_S

    def expired(self, stamp_s: float, now_s: float) -> bool:
        """Whether a frame stamped ``stamp_s``, admitted earlier, is past its deadline at ``now_s`` (older than
        ``max_age_s`` on the receive clock): the deadline its admission set, which the camera's worker honours when
        it comes to process the pair (no deadline without an age limit)."""
        return self.max_age_s > 0 and now_s - stamp_s > self.max_age_s


# ---------------------------------------------------------------------------------------------- master frames
def finite_stamp(stamp: object) -> float:
    """``stamp`` as a float, NaN when it is not a finite number (a frame refused as ``bad_stamp``)."""
    value = float(stamp) if isinstance(stamp, int | float) else math.nan
    return value if math.isfinite(value) else math.nan


APPLIED, APPLIED_LATE, REJECTED_LATE, REJECTED_FUTURE = "applied", "applied_late", "rejected_late", "rejected_future"


@dataclass(frozen=True, slots=True)
class ClockVerdict:
    """The tracker clock's verdict on a stamp: ``status`` (the tracker's FrameStatus value); ``resync``: the clock
    follows a jump; ``reset``: it jumped backwards, every track goes and the clock is forgotten first."""

    status: str
    resync: bool = False
    reset: bool = False

    @property
    def accepted(self) -> bool:
        return self.status in (APPLIED, APPLIED_LATE)


_C_APPLIED = ClockVerdict(APPLIED)
_C_APPLIED_LATE = ClockVerdict(APPLIED_LATE)
_C_REJECTED_LATE = ClockVerdict(REJECTED_LATE)
_C_REJECTED_FUTURE = ClockVerdict(REJECTED_FUTURE)
_C_RESYNC_FORWARD = ClockVerdict(APPLIED, resync=True)
_C_RESYNC_BACKWARD = ClockVerdict(APPLIED, resync=True, reset=True)


class StampClock:
    """The tracker clock (the newest applied stamp; no wall clock) and the run of refused stamps that may re-base
    it: frames up to ``max_delay_s`` older are applied late, older ones and those more than ``max_future_s`` ahead
    are refused; ``resync_frames`` consecutive refusals in one direction are a clock jump (cameras restarted after
    an idle period, a bag replay looping back) and the clock follows."""

    def __init__(self, max_delay_s: float, max_future_s: float, resync_frames: int) -> None:
        self._max_delay_s = max_delay_s
        self._max_future_s = max_future_s
        self._resync_frames = resync_frames
        self.now: float | None = None  # newest applied stamp (None before the first frame)
        self._reject_run = 0
        self._reject_dir = 0  # +1 future, -1 late

    def admit(self, stamp: float, resync_backward: bool = True) -> ClockVerdict:
        """Classify ``stamp``; does not move the clock (see :meth:`follow`). ``resync_backward`` False: late
        stamps never re-base the clock (the caller's clock judges stamps too: a camera that lags is refused, it
        cannot make the tracker start afresh)."""
        if self.now is None:
            self._reject_run = 0
            return _C_APPLIED
        if stamp > self.now + self._max_future_s + EPS_S:
            direction = 1
        elif stamp < self.now - self._max_delay_s - EPS_S:
            direction = -1
        else:
            self._reject_run = 0
            return _C_APPLIED_LATE if stamp < self.now else _C_APPLIED
        self._reject_run = self._reject_run + 1 if direction == self._reject_dir else 1
        self._reject_dir = direction
        if self._resync_frames and self._reject_run >= self._resync_frames and (direction > 0 or resync_backward):
            self._reject_run = 0
            # forward: an idle gap, time simply passed (lifecycle timeouts apply normally);
            # backward: time went back, start afresh
            return _C_RESYNC_FORWARD if direction > 0 else _C_RESYNC_BACKWARD
        return _C_REJECTED_FUTURE if direction > 0 else _C_REJECTED_LATE

    def follow(self, stamp: float) -> None:
        """Move the clock to ``stamp`` if that is newer."""
        if self.now is None or stamp > self.now:
            self.now = stamp

    def reset(self) -> None:
        """Forget the clock (and the run of refusals)."""
        self.now = None
        self._reject_run = 0


@dataclass(frozen=True, slots=True)
class FrameVerdict:
    """The master's verdict on a frame's stamp: the stamp it is applied at, or the refusal's ``code`` and
    ``reason``; ``clock_went_back``: the caller's clock went back (tracking starts afresh first); ``clamped``:
    applied at the caller's clock (it was a little ahead); ``tracker``: the tracker clock's verdict (None when
    refused before it)."""

    stamp_s: float
    code: str = ""  # '' = admitted by the caller's clock
    reason: str = ""
    clock_went_back: bool = False
    clamped: bool = False
    tracker: ClockVerdict | None = None

    @property
    def admitted(self) -> bool:
        return not self.code and self.tracker is not None and self.tracker.accepted


class FrameStampGate:
    """The master's rules on frame stamps (see the module doc) and both clocks they compare against: the caller's
    (the last receive / tick time seen) and the tracker's (:attr:`tracker_clock`, moved by the tracker)."""

    def __init__(self, max_age_s: float, max_future_s: float, max_delay_s: float, tracker_future_s: float,
                 resync_frames: int) -> None:
        self.max_age_s = max_age_s
        self.max_future_s = max_future_s
        self.max_delay_s = max_delay_s
        self.tracker_clock = StampClock(max_delay_s, tracker_future_s, resync_frames)
        self._last_now_s = -math.inf  # the caller's clock at the last frame or tick (live)

    def admit(self, stamp: float, now_s: float | None) -> FrameVerdict:
        """The verdict on a finite ``stamp`` at the caller's clock ``now_s`` (None: offline, stamps are the clock)."""
        if now_s is None:
            return FrameVerdict(stamp, tracker=self.tracker_clock.admit(stamp, resync_backward=True))
        if stamp < now_s - self.max_age_s:
            return FrameVerdict(stamp, "stale_stamp", f"stamp {now_s - stamp:.2f} s in the past (> max_stamp_age_s)")
        if stamp > now_s + self.max_future_s:
            return FrameVerdict(stamp, "future_stamp",
                                f"stamp {stamp - now_s:.2f} s in the future (> max_stamp_future_s)")
        went_back = self.clock_went_back(now_s)
        clamped = stamp > now_s  # no camera moves the tracker clock past the master's: others' frames stay on time
        stamp = now_s if clamped else stamp
        # the caller's clock went back: the tracker starts afresh (its clock forgotten) before this frame
        tracker = _C_APPLIED if went_back else self.tracker_clock.admit(stamp, resync_backward=False)
        return FrameVerdict(stamp, clock_went_back=went_back, clamped=clamped, tracker=tracker)

    def clock_went_back(self, now_s: float) -> bool:
        """Whether the caller's clock ``now_s`` (a frame's receive time, or a tick's) is behind the last one by
        more than ``max_detection_delay_s`` (a step back, a simulated time restarted: tracking must start
        afresh); it becomes the last one."""
        went_back = now_s < self._last_now_s - self.max_delay_s
        self._last_now_s = now_s
        return went_back
