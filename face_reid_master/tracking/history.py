"""Per-track history, so that a late frame (within ``max_detection_delay_s``) is applied exactly.

Each track keeps its recent filter steps (measurement and posterior) in stamp order.  A late frame
is gated against each track's newest posterior at or before its stamp (:meth:`TrackHistory.anchor`,
predicted forward); a matched track inserts the measurement in stamp order and re-runs its filter
over the few later steps (:func:`insert_late`), which gives exactly the state of processing that
track's measurements in stamp order.  History older than the delay bound is pruned.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from face_reid_master.tracking.kalman import ConstantVelocityModel

__all__ = ["FilterStep", "TrackHistory", "insert_late", "record_updates"]

FloatArray = NDArray[np.float64]


@dataclass(slots=True)
class FilterStep:
    """One filter step of a track: measurement ``z`` (2,) with variance ``r2`` at ``stamp_s``, and the
    posterior ``x`` (4,) / ``P`` (4, 4) after it."""

    stamp_s: float
    z: FloatArray
    r2: float
    x: FloatArray
    P: FloatArray


@dataclass(slots=True)
class TrackHistory:
    """Python-side record of one track (its numeric state lives in the Tracker's stacked arrays).

    ``steps`` in stamp order (``stamps`` mirrors their stamps, for bisection); ``cameras``: camera id ->
    newest stamp it detected the track; ``height_m`` measured at ``height_stamp_s``.
    """

    steps: list[FilterStep]
    stamps: list[float]
    cameras: dict[str, float] = field(default_factory=dict)
    height_m: float = float("nan")
    height_stamp_s: float = -math.inf

    def anchor(self, stamp: float) -> FilterStep:
        """The newest step at or before ``stamp`` (the first step if the track was born after it)."""
        if self.stamps[-1] <= stamp:
            return self.steps[-1]
        return self.steps[max(bisect.bisect_right(self.stamps, stamp) - 1, 0)]

    def prune(self, cutoff: float) -> None:
        """Drop steps older than ``cutoff``, keeping the newest one before it as anchor."""
        k = bisect.bisect_left(self.stamps, cutoff) - 1
        if k > 0:
            del self.steps[:k]
            del self.stamps[:k]


def record_updates(
    histories: Sequence[TrackHistory],
    stamp: float,
    z: FloatArray,
    r2: Sequence[float],
    x: FloatArray,
    P: FloatArray,
    cutoff: float,
) -> None:
    """Append an in-order step (row k of ``z`` / ``r2`` / ``x`` / ``P``) to ``histories[k]``; prune."""
    for k, hist in enumerate(histories):
        hist.steps.append(FilterStep(stamp, z[k], r2[k], x[k], P[k]))
        stamps = hist.stamps
        stamps.append(stamp)
        if len(stamps) > 2 and stamps[1] < cutoff:
            hist.prune(cutoff)


def insert_late(
    model: ConstantVelocityModel,
    histories: Sequence[TrackHistory],
    stamp: float,
    z: FloatArray,
    r2: FloatArray,
    x_pred: FloatArray,
    P_pred: FloatArray,
    cutoff: float,
) -> list[FilterStep]:
    """Insert late measurements ``z`` (k, 2) / ``r2`` (k,) at ``stamp`` into ``histories``, re-filter.

    ``x_pred`` / ``P_pred`` rows are the tracks' anchors predicted to ``stamp``; a track born after
    ``stamp`` is re-initialised from the late detection instead.  The re-filtering is batched across
    tracks, one step at a time.  Returns each history's newest step (the track's new state).
    """
    ks = [bisect.bisect_right(hist.stamps, stamp) for hist in histories]
    x_new, P_new = model.update(x_pred, P_pred, z, r2)
    born_after = np.array([k == 0 for k in ks])
    if born_after.any():  # earlier than the track's first detection: it becomes the new first one
        x_new[born_after], P_new[born_after] = model.initial_state(z[born_after], r2[born_after])
    r2_list = r2.tolist()
    for n, (hist, k) in enumerate(zip(histories, ks, strict=True)):
        hist.steps.insert(k, FilterStep(stamp, z[n], r2_list[n], x_new[n], P_new[n]))
        hist.stamps.insert(k, stamp)
    prev_x, prev_P = x_new.copy(), P_new.copy()  # working copies: the steps keep x_new's rows
    prev_t = np.full(len(histories), stamp)
    pos = ks
    while True:
        todo = [n for n, hist in enumerate(histories) if pos[n] + 1 < len(hist.steps)]
        if not todo:
            break
        steps = [histories[n].steps[pos[n] + 1] for n in todo]
        idx = np.array(todo)
        t_e = np.array([s.stamp_s for s in steps])
        xp, Pp = model.predict(prev_x[idx], prev_P[idx], t_e - prev_t[idx])
        xu, Pu = model.update(xp, Pp, np.array([s.z for s in steps]), np.array([s.r2 for s in steps]))
        for m, n in enumerate(todo):
            pos[n] += 1
            steps[m].x, steps[m].P = xu[m], Pu[m]
        prev_x[idx], prev_P[idx], prev_t[idx] = xu, Pu, t_e
    heads = [hist.steps[-1] for hist in histories]
    for hist in histories:
        hist.prune(cutoff)
    return heads
