"""Track lifecycle TENTATIVE -> CONFIRMED -> LOST -> DELETED, over the tracker's stacked (N,) arrays.

A tentative track is confirmed by ``detections_to_confirm`` hits within ``confirm_window_s`` of its
creation, else deleted; a confirmed one unseen for ``lost_after_s`` becomes LOST (and CONFIRMED again
when detected), and is deleted after ``delete_after_s`` more.  A tentative track that comes within
``min_person_separation_m`` of a confirmed one is a duplicate of that person and is deleted (merged);
new tracks start only from leftover detections that far from each other (:func:`birth_candidates`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import TrackState

__all__ = ["EPS_S", "Transitions", "birth_candidates", "expired", "transitions"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

EPS_S = 1e-9  # tolerance on time comparisons, so that "exactly lost_after_s later" counts

_TENTATIVE = int(TrackState.TENTATIVE)
_CONFIRMED = int(TrackState.CONFIRMED)
_LOST = int(TrackState.LOST)


@dataclass(frozen=True, slots=True)
class Transitions:
    """Masks over the tracks of one :func:`transitions` call (``lost`` excludes the ``dead``)."""

    confirmed: BoolArray
    lost: BoolArray
    recovered: BoolArray
    dead: BoolArray
    merged: int  # tentative duplicates among ``dead``


def expired(
    state: NDArray[np.int8], created: FloatArray, last_seen: FloatArray, now: float, cfg: TrackerConfig
) -> BoolArray:
    """Tracks timed out at ``now``: unconfirmed past the window, or unseen lost+delete seconds."""
    tentative = state == _TENTATIVE
    return (tentative & (now - created > cfg.confirm_window_s + EPS_S)) | (
        ~tentative & (now - last_seen >= cfg.lost_after_s + cfg.delete_after_s - EPS_S)
    )


def transitions(
    state: NDArray[np.int8],
    hits: NDArray[np.int64],
    created: FloatArray,
    last_seen: FloatArray,
    x: FloatArray,
    t: FloatArray,
    now: float,
    cfg: TrackerConfig,
) -> Transitions:
    """Apply the transitions due at ``now`` to ``state`` (in place); ``x`` / ``t``: newest posteriors."""
    unseen = now - last_seen
    tent = state == _TENTATIVE
    merged = np.zeros_like(tent)
    established = state == _CONFIRMED
    if tent.any() and established.any():
        pos = x[:, :2] + x[:, 2:] * (now - t)[:, None]
        gap2 = ((pos[tent][:, None, :] - pos[established][None, :, :]) ** 2).sum(axis=2)
        merged[tent] = (gap2 < cfg.min_person_separation_m**2).any(axis=1)
    conf = (
        tent
        & ~merged
        & (hits >= cfg.detections_to_confirm)
        & (last_seen - created <= cfg.confirm_window_s + EPS_S)
    )
    state[conf] = _CONFIRMED
    lost = (state == _CONFIRMED) & (unseen >= cfg.lost_after_s - EPS_S)
    recovered = (state == _LOST) & (unseen < cfg.lost_after_s - EPS_S)
    state[lost] = _LOST
    state[recovered] = _CONFIRMED
    dead = merged | expired(state, created, last_seen, now, cfg)
    return Transitions(conf, lost & ~dead, recovered, dead, int(merged.sum()))


def birth_candidates(z: FloatArray, cols: NDArray[np.intp], min_separation_m: float) -> NDArray[np.intp]:
    """Greedily keep the detections ``z[cols]`` at least ``min_separation_m`` from each other."""
    if cols.shape[0] < 2:
        return cols
    zc = z[cols]
    d2 = ((zc[:, None, :] - zc[None, :, :]) ** 2).sum(axis=2)
    close = d2 < min_separation_m**2
    if close.sum() == cols.shape[0]:  # only the diagonal
        return cols
    keep: list[int] = []
    for k in range(cols.shape[0]):
        if not any(close[k, j] for j in keep):
            keep.append(k)
    return cols[keep]
