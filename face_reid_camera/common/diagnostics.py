"""Health of a running node as plain data: rolling timing percentiles, rates, and one report per period.

Pure Python (no rclpy): the nodes fill a :class:`NodeHealth`, ``face_reid_camera.common.ros.lifecycle``
turns its :class:`DiagnosticReport` into ``diagnostic_msgs/DiagnosticArray`` on ``/diagnostics``.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["DiagnosticLevel", "DiagnosticReport", "NodeHealth", "RollingWindow"]


class DiagnosticLevel(enum.IntEnum):
    """The levels of diagnostic_msgs/DiagnosticStatus."""

    OK = 0
    WARN = 1
    ERROR = 2


class RollingWindow:
    """The last ``size`` values of a quantity (e.g. processing times), with percentiles and mean."""

    def __init__(self, size: int = 300) -> None:
        if size < 1:
            raise ValueError(f"size must be >= 1, got {size}")
        self._values: deque[float] = deque(maxlen=size)

    def add(self, value: float) -> None:
        self._values.append(float(value))

    def __len__(self) -> int:
        return len(self._values)

    def percentile(self, q: float) -> float:
        """The q-th percentile (0..100) of the window; NaN when empty."""
        return float(np.percentile(np.fromiter(self._values, float), q)) if self._values else float("nan")

    def mean(self) -> float:
        return float(np.mean(np.fromiter(self._values, float))) if self._values else float("nan")


@dataclass(frozen=True)
class DiagnosticReport:
    """One node's status: level, one-line message (the warnings joined), and key/value fields."""

    name: str
    hardware_id: str
    level: DiagnosticLevel
    message: str
    values: Mapping[str, str]


@dataclass
class NodeHealth:
    """What a node counts between reports: inputs, processed/dropped frames, timings, rejections by reason.

    The node calls :meth:`frame_in`, :meth:`frame_processed`, :meth:`reject` and :meth:`published` as things
    happen (times in seconds of the node's clock), sets ``frames_dropped`` (only it can count them), and
    calls :meth:`report` once per period. Totals are since start; rates are over the last report period.
    """

    name: str
    hardware_id: str
    no_input_warning_s: float = 5.0
    timings_ms: RollingWindow = field(default_factory=RollingWindow)
    people_per_frame: RollingWindow = field(default_factory=RollingWindow)
    faces_per_frame: RollingWindow = field(default_factory=RollingWindow)
    frames_in: int = 0
    frames_processed: int = 0
    frames_dropped: int = 0
    messages_published: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    started_s: float | None = None
    last_input_s: float | None = None
    _last_report_s: float | None = None
    _published_at_last_report: int = 0

    def start(self, now_s: float) -> None:
        """(Re)start the no-input clock, e.g. on activation."""
        self.started_s = now_s
        self._last_report_s = now_s
        self._published_at_last_report = self.messages_published

    def frame_in(self, now_s: float) -> None:
        self.frames_in += 1
        self.last_input_s = now_s

    def frame_processed(self, processing_ms: float, people: int, faces: int) -> None:
        self.frames_processed += 1
        self.timings_ms.add(processing_ms)
        self.people_per_frame.add(people)
        self.faces_per_frame.add(faces)

    def reject(self, reason: str) -> int:
        """Count one rejected input of ``reason``; returns the total for that reason."""
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        return self.rejected[reason]

    def published(self) -> None:
        self.messages_published += 1

    def report(self, now_s: float, extra: Mapping[str, object] | None = None,
               warnings: list[str] | None = None, errors: list[str] | None = None) -> DiagnosticReport:
        """The status now: ERROR when an error is given (said first), else WARN when nothing arrived for
        ``no_input_warning_s`` or a warning is given."""
        warnings = list(warnings or [])
        since = self.last_input_s if self.last_input_s is not None else self.started_s
        if since is not None and now_s - since > self.no_input_warning_s:
            warnings.insert(0, f"no input for {now_s - since:.1f} s")
        period = now_s - self._last_report_s if self._last_report_s is not None else 0.0
        rate = (self.messages_published - self._published_at_last_report) / period if period > 0 else 0.0
        self._last_report_s = now_s
        self._published_at_last_report = self.messages_published
        values: dict[str, object] = {
            "frames_in": self.frames_in,
            "frames_processed": self.frames_processed,
            "frames_dropped": self.frames_dropped,
            "processing_time_p50_ms": self.timings_ms.percentile(50),
            "processing_time_p95_ms": self.timings_ms.percentile(95),
            "people_per_frame": self.people_per_frame.mean(),
            "faces_per_frame": self.faces_per_frame.mean(),
            "publish_rate_hz": rate,
            "messages_published": self.messages_published,
            "rejected_total": sum(self.rejected.values()),
        }
        values.update({f"rejected_{k}": v for k, v in sorted(self.rejected.items())})
        values.update(extra or {})
        said = [*(errors or []), *warnings]
        level = DiagnosticLevel.ERROR if errors else DiagnosticLevel.WARN if warnings else DiagnosticLevel.OK
        return DiagnosticReport(self.name, self.hardware_id, level, "; ".join(said) if said else "ok",
                                {k: _fmt(v) for k, v in values.items()})


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return "nan" if value != value else f"{value:.3f}"
    return str(value)
