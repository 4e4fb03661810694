"""Rank-1 of a body metric on a scenario's own bodies: thinning, same-camera exclusion, days as clothes."""

from __future__ import annotations

import numpy as np

from face_reid_master.body.metric_file import default_body_metric
from face_reid_master.evaluation.body_rank import scenario_bodies, scenario_rank1
from face_reid_master.records import BodyRecord, CameraFrameRecord, PersonRecord

METRIC = default_body_metric()
GEOMETRY = np.full(6, np.nan, np.float32)


def _frames(looks: np.ndarray, stamps: list[float], cameras: tuple[str, ...]) -> tuple[list, list]:
    frames, gts = [], []
    for t in stamps:
        for cam in cameras:
            people = tuple(PersonRecord(np.array([float(k), 0.0, 0.0]), body=BodyRecord(
                looks[k], METRIC.space, 1.0, GEOMETRY)) for k in range(looks.shape[0]))
            frames.append(CameraFrameRecord(cam, t, people))
            gts.append(np.arange(looks.shape[0]))
    return frames, gts


def test_rank1_counts_the_nearest_body_of_another_camera() -> None:
    rng = np.random.default_rng(0)
    looks = rng.normal(0.0, 1.0, (4, METRIC.length)).astype(np.float32)
    frames, gts = _frames(looks, [0.0, 0.5, 3.0], ("a", "b"))
    bodies = scenario_bodies(frames, gts, METRIC.space, thin_s=2.0)
    assert bodies.labels.size == 4 * 2 * 2  # 0.5 s is within the 2 s thinning: dropped
    assert scenario_rank1(bodies, METRIC.features["fused"]) == 1.0
    # camera b sees persons 0 and 1 in each other's clothes: their probes find the other person
    swapped = [CameraFrameRecord(f.camera_id, f.stamp_s, (f.people[1], f.people[0], *f.people[2:]))
               if f.camera_id == "b" else f for f in frames]
    assert scenario_rank1(scenario_bodies(swapped, gts, METRIC.space, thin_s=2.0), METRIC.features["fused"]) == 0.5


def test_one_camera_or_another_space_gives_no_rank() -> None:
    looks = np.ones((2, METRIC.length), np.float32)
    frames, gts = _frames(looks, [0.0, 3.0], ("a",))
    assert scenario_rank1(scenario_bodies(frames, gts, METRIC.space), METRIC.features["fused"]) is None
    assert scenario_bodies(frames, gts, "another_space").labels.size == 0
