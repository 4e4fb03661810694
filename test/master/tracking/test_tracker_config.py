"""Tracker parameters (tracking.config): the chi-square gate and validation naming the field."""

from __future__ import annotations

import math

import pytest
from scipy.stats import chi2

from face_reid_master.tracking.config import TrackerConfig


def test_gate_is_chi_square_quantile_with_two_dof() -> None:
    assert (
        TrackerConfig().gate_mahalanobis_sq
        == pytest.approx(chi2.ppf(0.99, 2))
        == pytest.approx(9.2103, abs=1e-4)
    )
    assert TrackerConfig(gate_probability=0.95).gate_mahalanobis_sq == pytest.approx(-2 * math.log(0.05))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"gate_probability": 1.0},
        {"gate_probability": 0.0},
        {"lost_after_s": 0.0},
        {"delete_after_s": -1.0},
        {"confirm_window_s": math.inf},
        {"max_detection_delay_s": math.nan},
        {"detections_to_confirm": 0},
        {"detections_to_confirm": 2.5},
        {"max_tracks": 0},
        {"clock_resync_frames": -1},
        {"accel_noise_mps2": "1"},
        {"max_gate_distance_m": 0.0},
        {"min_person_separation_m": -0.1},
    ],
)
def test_config_rejects_bad_values_naming_the_field(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        TrackerConfig(**kwargs)  # type: ignore[arg-type]
