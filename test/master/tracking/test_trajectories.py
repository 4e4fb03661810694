"""The synthetic trajectory generator (``trajectories.py``) the tracker tests are driven by."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trajectories import (
    CameraFov,
    Scenario,
    Walker,
    crossing_pair,
    min_pair_distance,
    random_walkers,
)


def test_generator_is_deterministic_and_respects_fields_of_view() -> None:
    cams = (CameraFov("a", (0.0, -5.0), math.pi / 2, math.radians(60), 6.0),)
    walker = Walker(1, ((-6.0, 0.0), (6.0, 0.0)), 1.2)
    sc = Scenario((walker,), cams, 8.0, noise_std_m=0.0, miss_probability=0.3, seed=4)
    f1, f2 = sc.frames(), sc.frames()
    assert [(f.stamp_s, f.gt_ids) for f in f1] == [(f.stamp_s, f.gt_ids) for f in f2]
    seen = [f for f in f1 if f.gt_ids]
    # A 60 degree wedge 5 m away spans |x| <= 5 tan 30 = 2.89 m; misses thin the detections out.
    xs = np.array([f.detections[0].position_xy[0] for f in seen])
    assert np.abs(xs).max() <= 5 * math.tan(math.radians(30)) + 1e-9
    in_view = [f for f in f1 if abs(walker.position(f.stamp_s)[0]) < 2.8]  # type: ignore[index]
    assert 0.6 < len(seen) / len(in_view) < 0.8
    assert [f.gt_ids for f in Scenario((walker,), cams, 8.0, miss_probability=0.3, seed=5).frames()] != [
        f.gt_ids for f in f1
    ]


def test_random_walkers_keep_their_separation_and_crossings_meet() -> None:
    assert min_pair_distance(random_walkers(4, seed=3)) >= 0.6
    assert min_pair_distance(crossing_pair(90.0)) < 0.05
    assert min_pair_distance(crossing_pair(45.0, min_separation_m=0.5)) == pytest.approx(0.5, abs=0.03)
    assert min_pair_distance(crossing_pair(180.0, min_separation_m=0.5)) == pytest.approx(0.5, abs=0.03)
