"""Feature funnel (second seed, Algorithm 2) and the height evidence of faceless tracks."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.feature_funnel import funnel_survivors, gaussian_log_ratio
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal

BODY_LIKELIHOOD = LikelihoodModel(SkewNormal(0.0, 0.4, 0.15), SkewNormal(0.0, 1.2, 0.25))  # N_p = N_n near 0.75
RED = np.array([[1.0, 0, 0, 0]], np.float32)


def test_each_level_prunes_relative_to_its_nearest_candidate() -> None:
    appearance = [[0.2, 0.25, 0.9, np.nan]]  # the 4th candidate was not measured: never pruned
    height = [[0.30, 0.01, 0.0, 0.015]]
    keep = funnel_survivors([appearance, height], [1.5])
    assert keep.tolist() == [[True, True, False, True]]
    keep3 = funnel_survivors([appearance, height, [[0, 0, 0, 0]]], [1.5, 2.0])
    assert keep3.tolist() == [[False, True, False, True]]  # 0.30 > 2 x 0.01: height prunes the first
    with pytest.raises(ValueError, match="one factor per level"):
        funnel_survivors([appearance, height], [])
    with pytest.raises(ValueError, match="alpha must be > 1"):
        funnel_survivors([appearance, height], [1.0])


def test_the_height_ratio_favours_small_differences_and_crosses_zero_where_the_densities_meet() -> None:
    lr = gaussian_log_ratio([0.0, 0.05, 0.3], 0.05, 0.12)
    assert lr[0] > lr[1] > 0 > lr[2]
    d = np.sqrt(2 * np.log(0.12 / 0.05) / (1 / 0.05**2 - 1 / 0.12**2))
    assert abs(float(gaussian_log_ratio(d, 0.05, 0.12))) < 1e-9


def test_height_tells_apart_two_people_in_the_same_clothes() -> None:
    body = BodyEvidence(BODY_LIKELIHOOD, window_s=100.0, min_observations=3, max_log_ratio=3.0)
    body.add_face_bodies(1, RED, 0.0, heights=[1.62])
    body.add_face_bodies(2, RED, 0.0, heights=[1.85])
    for k in range(4):
        body.observe(7, RED + 0.02, 1.0 + k, [1, 2], heights=[1.84])
    ((track, face, _),) = body.decide([1, 2], 5.0)
    assert (track, face) == (7, 2)


def test_the_funnel_abandons_a_face_that_only_height_would_favour() -> None:
    """Face 2's person is as tall as the track but wears other clothes (appearance distance beyond
    funnel_alpha x face 1's): the funnel drops it at the appearance level, so it gets the bound against it
    whatever its height says; within funnel_alpha its height counts."""
    body = BodyEvidence(BODY_LIKELIHOOD, window_s=100.0, min_observations=1, max_log_ratio=3.0, funnel_alpha=1.5)
    heights = np.array([[0.24, 0.0]])  # the track is 0.24 m taller than face 1's person, as tall as face 2's
    far = body._log_ratios(np.array([[0.2, 0.31]]), heights)
    near = body._log_ratios(np.array([[0.2, 0.29]]), heights)
    assert far[0, 1] == -3.0 and near[0, 1] > -3.0
    assert near[0, 1] > near[0, 0]  # within the funnel, height favours face 2
