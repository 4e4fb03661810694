"""Data association of one camera frame: which detection belongs to which predicted track (pure numpy).

Tracks are served in a cascade (as DeepSORT's matching cascade): CONFIRMED tracks detected within
``coast_after_s``, then the other CONFIRMED ones, then LOST, then TENTATIVE, so that neither a
coasting track whose person is gone nor a tentative duplicate takes the detection of a person whose
track is healthy.  Within a group, pass 1 is GNN inside the chi-square gate (and the metric gate) on
``d2 + log det S`` (the negative log-likelihood: with ``d2`` alone a vague track looks closer than a
precise one).  Pass 2 (not for LOST tracks) gives a leftover track a leftover detection within
``min_person_separation_m`` of its prediction (nobody else can be so close), inside the wider gate of
probability ``1 - (1 - gate_probability)**2`` (= twice the d2 gate for 2 dof), or within reach of its
last measured position (``min_person_separation_m + max_speed_mps * elapsed``, at most
``max_gate_distance_m``): the constant-velocity gate alone loses people who turn or stop, and noise
outliers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.kalman import mahalanobis_sq
from face_reid_master.tracking.records import TrackState

__all__ = ["Associator", "Matches", "gnn"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]

_TENTATIVE = int(TrackState.TENTATIVE)
_CONFIRMED = int(TrackState.CONFIRMED)
_LOST = int(TrackState.LOST)
_EMPTY = np.zeros(0, dtype=np.intp)


def gnn(cost: FloatArray, feasible: NDArray[np.bool_]) -> tuple[IndexArray, IndexArray]:
    """Global-nearest-neighbour assignment restricted to ``feasible`` pairs; (rows, cols) matched.

    Infeasible pairs cost more than any set of feasible ones, so the result has the maximum number
    of feasible matches and, among those, the minimum total cost (OpenPTrack-style GNN).
    """
    rows_ok = np.flatnonzero(feasible.any(axis=1))
    if rows_ok.shape[0] == 0:
        return _EMPTY, _EMPTY
    cols_ok = np.flatnonzero(feasible.any(axis=0))
    sub = cost[np.ix_(rows_ok, cols_ok)]
    sub_feasible = feasible[np.ix_(rows_ok, cols_ok)]
    lo, hi = sub[sub_feasible].min(), sub[sub_feasible].max()
    big = (hi - lo) * (min(sub.shape) + 1.0) + 1.0
    r, c = linear_sum_assignment(np.where(sub_feasible, sub - lo, big))
    keep = sub_feasible[r, c]
    return rows_ok[r[keep]], cols_ok[c[keep]]


@dataclass(frozen=True, slots=True)
class Matches:
    """``rows`` (tracks) matched to ``cols`` (detections); ``near``: (M,) detections within
    ``min_person_separation_m`` of some track's predicted position."""

    rows: IndexArray
    cols: IndexArray
    near: NDArray[np.bool_]


class Associator:
    """The association cascade of one :class:`TrackerConfig` (see the module doc)."""

    def __init__(self, config: TrackerConfig) -> None:
        self._gate = config.gate_mahalanobis_sq
        self._wide_gate = 2.0 * self._gate
        self._gate_m2 = config.max_gate_distance_m**2
        self._sep = config.min_person_separation_m
        self._sep2 = config.min_person_separation_m**2
        self._max_reach = max(config.max_gate_distance_m, config.min_person_separation_m)
        self._max_speed = config.max_speed_mps
        self._coast_after_s = config.coast_after_s

    def __call__(
        self,
        x_pred: FloatArray,
        P_pred: FloatArray,
        state: NDArray[np.int8],
        t_last: FloatArray,
        z_last: FloatArray,
        z: FloatArray,
        r2: FloatArray,
        stamp: float,
    ) -> Matches:
        """Associate detections ``z`` (M, 2) with variances ``r2`` (M,) at ``stamp`` to N tracks.

        ``x_pred`` (N, 4) / ``P_pred`` (N, 4, 4): the tracks predicted to ``stamp``; ``state`` (N,)
        their :class:`TrackState`; ``t_last`` (N,) / ``z_last`` (N, 2): stamp and position of each
        track's newest measurement at or before ``stamp`` (its first one if it was born later).
        """
        d2, log_det = mahalanobis_sq(x_pred[:, :2], P_pred[:, :2, :2], z, r2)
        dist2 = ((z[None, :, :] - x_pred[:, None, :2]) ** 2).sum(axis=2)
        close = dist2 < self._sep2
        near = close.any(axis=0)
        in_metric_gate = dist2 <= self._gate_m2
        feasible = (d2 <= self._gate) & in_metric_gate
        nll = d2 + log_det
        free_c = np.ones(d2.shape[1], dtype=bool)
        rows_l: list[IndexArray] = []
        cols_l: list[IndexArray] = []
        confirmed = state == _CONFIRMED
        fresh = stamp - t_last < self._coast_after_s
        groups = (
            (confirmed & fresh, True),
            (confirmed & ~fresh, True),
            (state == _LOST, False),
            (state == _TENTATIVE, True),
        )
        for group, second_pass in groups:
            if not group.any() or not free_c.any():
                continue
            r_, c_ = gnn(nll, feasible & group[:, None] & free_c[None, :])
            rows_l.append(r_)
            cols_l.append(c_)
            free_c[c_] = False
            if not second_pass or not free_c.any():
                continue
            group[r_] = False
            left_r = np.flatnonzero(group)
            if left_r.shape[0] == 0:
                continue
            reach = np.minimum(self._sep + self._max_speed * np.maximum(stamp - t_last[left_r], 0.0), self._max_reach)
            dist2_last = ((z[None, :, :] - z_last[left_r][:, None, :]) ** 2).sum(axis=2)
            near_pred = (close[left_r] | (d2[left_r] <= self._wide_gate)) & in_metric_gate[left_r]
            ok2 = (near_pred | (dist2_last < reach[:, None] ** 2)) & free_c[None, :]
            if ok2.any():
                r_, c_ = gnn(np.minimum(dist2[left_r], dist2_last), ok2)
                rows_l.append(left_r[r_])
                cols_l.append(c_)
                free_c[c_] = False
        rows = np.concatenate(rows_l) if rows_l else _EMPTY
        cols = np.concatenate(cols_l) if cols_l else _EMPTY
        return Matches(rows, cols, near)
