"""What the master's /diagnostics must say beyond the inputs: store failures, faces lost at open, overload, a
second master (or a keyless publisher of its tracks) on the domain. Pure (no rclpy): the node feeds
:class:`MasterHealthWatch` counters, it answers errors and warnings for
:meth:`~face_reid_camera.common.diagnostics.NodeHealth.report`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = ["HealthVerdict", "MasterHealthWatch"]

OVERLOAD_WARN_FRACTION = 0.05  # frames dropped for overload above this share of the frames in the window: WARN
OVERLOAD_WINDOW_S = 30.0  # the window of that share (s)
STORE_RECOVERED_WARN_S = 600.0  # a store write failure followed by successful writes stays a WARN this long (s)


@dataclass
class HealthVerdict:
    """Errors (the level becomes ERROR), warnings (WARN) and values for the report."""

    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    values: dict[str, object] = field(default_factory=dict)


def _plain(reason: str) -> str:
    """A store error as said on /diagnostics: ``disk full`` plainly when it is one."""
    reason = reason or "unknown reason"
    if "full" in reason.lower() or "no space" in reason.lower():
        return f"disk full ({reason})"
    return reason


class MasterHealthWatch:
    """Turns the master's counters into errors and warnings (see the module docstring).

    - the face store: its most recent write failed -> ERROR with the reason (``disk full`` said plainly);
      failures followed by a successful write -> WARN for ``recovered_warn_s`` after the last failure;
    - new face ids: the last reservation in the store failed (new people get no face id) -> ERROR with the reason;
    - faces lost at open (ids the store's ledger saved but the database lacks, a corrupt file moved aside)
      -> WARN for the rest of the run;
    - frames dropped for overload above ``overload_fraction`` of the frames received in the last ``window_s``
      -> WARN with the percentage;
    - other publishers of the master's output topic -> WARN naming them: a keyless participant when what they
      published so far never opened with the network key, else another master on the domain.
    """

    def __init__(self, overload_fraction: float = OVERLOAD_WARN_FRACTION, window_s: float = OVERLOAD_WINDOW_S,
                 recovered_warn_s: float = STORE_RECOVERED_WARN_S) -> None:
        if not 0.0 <= overload_fraction <= 1.0 or window_s <= 0.0 or recovered_warn_s < 0.0:
            raise ValueError("overload_fraction must be in [0, 1], window_s > 0 and recovered_warn_s >= 0")
        self.overload_fraction = overload_fraction
        self.window_s = window_s
        self.recovered_warn_s = recovered_warn_s
        self._frames: deque[tuple[float, int, int]] = deque()  # (now, frames in, dropped) totals
        self._store_failures = 0
        self._last_failure_s: float | None = None
        self._lost_at_open: list[str] = []

    def store_opened(self, lost_face_ids: Sequence[int] = (), recovered_from: object = None,
                     salvaged_face_ids: Sequence[int] = ()) -> None:
        """What the store found at open: ids saved before but missing (its last writes lost), a corrupt file moved
        aside (and how many faces were salvaged from it)."""
        self._lost_at_open = []
        if lost_face_ids:
            ids = ", ".join(map(str, list(lost_face_ids)[:10])) + (", ..." if len(lost_face_ids) > 10 else "")
            self._lost_at_open.append(f"{len(lost_face_ids)} learned face(s) lost at open (saved before, missing from "
                                      f"the database: its last writes were lost), ids {ids}")
        if recovered_from is not None:
            self._lost_at_open.append(f"the face database was corrupt: moved to {recovered_from}, "
                                      f"{len(salvaged_face_ids)} face(s) salvaged from it")

    def verdict(self, now_s: float, *, frames_in: int = 0, frames_dropped_overload: int = 0,
                store_write_failures: int = 0, store_last_write_ok: bool | None = None, store_last_error: str = "",
                faces_refused_no_id: int = 0, face_id_error: str = "", other_publishers: Sequence[str] = (),
                output_topic: str = "/tracks_named", others_opened: int = 0, others_unopened: int = 0) -> HealthVerdict:
        """Errors, warnings and values now (call about once a second with the totals since start).
        ``others_opened`` / ``others_unopened``: messages of other senders on a secured master's output topic
        that opened with the network key / did not."""
        out = HealthVerdict()
        self._store(now_s, store_write_failures, store_last_write_ok, store_last_error, out)
        if face_id_error:
            out.errors.append(f"new people get no face id ({faces_refused_no_id} refused so far): face ids cannot "
                              f"be reserved in the face store: {_plain(face_id_error)}")
        out.warnings += self._lost_at_open
        self._overload(now_s, frames_in, frames_dropped_overload, out)
        out.values["other_output_publishers"] = len(other_publishers)
        out.values["other_output_messages_unopened"] = others_unopened
        if other_publishers:
            names = ", ".join(sorted(other_publishers)[:5])
            if others_unopened and not others_opened:  # what it published is not a key holder's: not a master
                out.warnings.append(f"an unauthenticated publisher of {output_topic} on this domain ({names}): "
                                    f"{others_unopened} of its message(s) did not open with the network key (a "
                                    "keyless participant, not a second master); consumers with the key refuse them")
            else:
                out.warnings.append(f"another publisher of {output_topic} on this domain ({names}): two masters "
                                    "give the same people different track and face ids; run one master per domain")
        return out

    def _store(self, now_s: float, failures: int, last_ok: bool | None, last_error: str, out: HealthVerdict) -> None:
        if failures > self._store_failures:
            self._last_failure_s = now_s
        self._store_failures = max(self._store_failures, failures)
        out.values["store_write_failures"] = failures
        if not failures:
            return
        reason = _plain(last_error)
        if last_ok is False:
            out.errors.append(f"face store writes fail ({failures} so far): {reason}: learned faces are not saved")
        elif self._last_failure_s is not None and now_s - self._last_failure_s <= self.recovered_warn_s:
            out.warnings.append(f"{failures} face store write(s) failed, the writes since succeed (last failure: "
                                f"{reason})")

    def _overload(self, now_s: float, frames_in: int, dropped: int, out: HealthVerdict) -> None:
        frames = self._frames
        frames.append((now_s, frames_in, dropped))
        while len(frames) > 1 and frames[1][0] <= now_s - self.window_s:
            frames.popleft()
        _, in0, drop0 = frames[0]
        received, lost = frames_in - in0, dropped - drop0
        if len(frames) == 1:  # the first call: the totals since start
            received, lost = frames_in, dropped
        share = lost / received if received > 0 else 0.0
        out.values["frames_dropped_overload_window_pct"] = round(100.0 * share, 1)
        if received > 0 and share > self.overload_fraction:
            out.warnings.append(f"overloaded: {100.0 * share:.1f} % of the frames of the last {self.window_s:g} s "
                                f"dropped ({lost} of {received}; more than {100.0 * self.overload_fraction:g} %): "
                                "fewer cameras or frames per second, or a faster host")
