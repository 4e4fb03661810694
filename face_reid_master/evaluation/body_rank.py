"""Rank-1 of a body metric on a scenario's own bodies: how often the nearest body another camera saw is the
same person in the same clothes (a person's day counts as their clothes).

Bodies are thinned to one per person, camera and ``thin_s`` seconds (frames of one glance are near copies);
each kept body is a probe against the kept bodies of the other cameras.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_master.body.metric_file import BodyFeatureMetric
from face_reid_master.records import CameraFrameRecord

__all__ = ["ScenarioBodies", "scenario_bodies", "scenario_rank1"]


@dataclass(frozen=True)
class ScenarioBodies:
    """Thinned wire descriptors (n, length) with their label (person * 1000 + day) and camera index."""

    wire: npt.NDArray[np.float32]
    labels: npt.NDArray[np.int64]
    cameras: npt.NDArray[np.int64]


def scenario_bodies(frames: Sequence[CameraFrameRecord], frame_gt_ids: Sequence[npt.NDArray[np.integer]],
                    space: str, days: Sequence[tuple[int, float, float, Sequence[int]]] = (),
                    thin_s: float = 2.0) -> ScenarioBodies:
    """The scenario's bodies of projection ``space`` (false positives and undescribed people left out)."""
    last: dict[tuple[int, str], float] = {}
    camera_index: dict[str, int] = {}
    wire, labels, cameras = [], [], []
    for frame, gt in zip(frames, frame_gt_ids, strict=True):
        day = next((d for d, a, b, _ in days if a <= frame.stamp_s <= b), 0)
        for person, g in zip(frame.people, np.asarray(gt).tolist(), strict=True):
            body = person.body
            if g < 0 or body is None or body.space != space or not len(body.descriptor):
                continue
            key = (int(g), frame.camera_id)
            if frame.stamp_s < last.get(key, -np.inf) + thin_s:
                continue
            d = np.asarray(body.descriptor, dtype=np.float32)
            if not np.isfinite(d).all():
                continue
            last[key] = frame.stamp_s
            wire.append(d)
            labels.append(int(g) * 1000 + int(day))
            cameras.append(camera_index.setdefault(frame.camera_id, len(camera_index)))
    if not wire:
        return ScenarioBodies(np.zeros((0, 0), np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64))
    return ScenarioBodies(np.stack(wire), np.array(labels, np.int64), np.array(cameras, np.int64))


def scenario_rank1(bodies: ScenarioBodies, feature: BodyFeatureMetric) -> float | None:
    """Share of the bodies whose nearest body of another camera is the same person and day (None: no probe
    has one)."""
    if bodies.wire.shape[0] < 2:
        return None
    e = feature.embed(bodies.wire).astype(np.float64)
    sq = (e * e).sum(axis=1)
    d2 = sq[:, None] + sq[None, :] - 2.0 * e @ e.T
    d2[bodies.cameras[:, None] == bodies.cameras[None, :]] = np.inf
    has_other = np.isfinite(d2).any(axis=1)
    # probes whose person another camera saw at all
    same_other = (bodies.labels[:, None] == bodies.labels[None, :]) & np.isfinite(d2)
    probes = has_other & same_other.any(axis=1)
    if not probes.any():
        return None
    nearest = np.argmin(d2[probes], axis=1)
    return float(np.mean(bodies.labels[probes] == bodies.labels[nearest]))
