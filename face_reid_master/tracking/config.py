"""Tracker parameters (the ROS parameters ``tracker.*``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.stats import chi2

from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.tracking.kalman import ConstantVelocityModel

__all__ = ["TrackerConfig"]

@dataclass(frozen=True)
class TrackerConfig:
    """Tracker parameters, the ROS parameters ``tracker.*``: each declared once with its unit and range
    (ValueError on a bad value); docs/tuning.md says why some are what they are."""

    accel_noise_mps2: float = param(
        1.0, "Kalman white-acceleration noise std over 1 s (m/s^2).",
        low=0.0, high=100.0, low_open=True)
    init_velocity_std_mps: float = param(
        1.0, "Velocity prior std of a new track (m/s).",
        low=0.0, high=100.0, low_open=True)
    gate_probability: float = param(
        0.99, "Chi-square (2 dof) gate: detections outside this probability are not associated (0..1).",
        low=0.0, high=1.0, low_open=True, high_open=True)
    detections_to_confirm: int = param(
        3, "Detections within confirm_window_s that confirm a new track (count).",
        low=1, high=1000)
    confirm_window_s: float = param(
        1.0, "A tentative track not confirmed within this time is deleted (s).",
        low=0.0, high=3600.0, low_open=True)
    lost_after_s: float = param(
        1.0, "A confirmed track without detections for this long becomes LOST (s).",
        low=0.0, high=3600.0, low_open=True)
    delete_after_s: float = param(
        3.0, "A LOST track is deleted after this much longer; its face is released (s).",
        low=0.0, high=86400.0)
    max_detection_delay_s: float = param(
        0.3, "Frames up to this much older than the newest are applied in stamp order (s).",
        low=0.0, high=60.0)
    max_future_stamp_s: float = param(
        2.0, "Frames further ahead of the newest stamp are rejected (s).",
        low=0.0, high=3600.0)
    clock_resync_frames: int = param(
        5, "Consecutive rejected frames taken as a clock jump (count; 0 = never).",
        low=0, high=100000)
    max_gate_distance_m: float = param(
        1.0, "Euclidean gate around a track's predicted position (m; inf = off).",
        low=0.0, high=math.inf, low_open=True)
    min_person_separation_m: float = param(
        0.4, "Two people are assumed never closer than this (m).",
        low=0.0, high=10.0)
    max_speed_mps: float = param(
        2.0, "Fastest walking speed assumed when re-gating turning/stopping people (m/s).",
        low=0.0, high=100.0)
    coast_after_s: float = param(
        0.25, "Confirmed tracks undetected this long get detections after fresh ones (s).",
        low=0.0, high=3600.0)
    camera_window_s: float = param(
        0.5, "A track's cameras are those that detected it within this window (s).",
        low=0.0, high=3600.0)
    max_tracks: int = param(
        200, "Cap on live tracks; extra detections are dropped and counted (count).",
        low=1, high=100000)
    appearance_gate: float = param(
        1.0, "Track and detection farther apart than this in body appearance are never associated (metric "
        "units: 1 = median different-person distance; inf = off).", low=0.0, high=math.inf, low_open=True)
    appearance_weight: float = param(
        4.0, "Association cost per unit of body-appearance distance (0 = appearance only gates).",
        low=0.0, high=1000.0)
    appearance_match_distance: float = param(
        0.7, "Body-appearance distance of one person: LOST tracks re-attach below it; the cost of an unknown "
        "distance (metric units).", low=0.0, high=10.0)
    appearance_gallery_size: int = param(
        16, "Body-appearance embeddings kept per track (count).", low=1, high=1000)
    stray_log_odds: float = param(
        -2.5, "Log odds that a detection a track takes is a person it was not following, at a pair negative "
        "log-likelihood (d2 + log det S, S in m^2) of 0 and the appearance distance stray_appearance_distance; "
        "each unit of that log-likelihood adds 0.5 (chosen on development scenarios; lower = fewer releases).",
        low=-100.0, high=100.0)
    stray_appearance_slope: float = param(
        9.6, "Log odds of a stray per unit of body-appearance distance above stray_appearance_distance (per "
        "metric unit; 0 = position only).", low=0.0, high=1000.0)
    stray_appearance_distance: float = param(
        0.45, "Body-appearance distance between a track and its detection that says nothing of a stray (metric "
        "units).", low=0.0, high=10.0)
    stray_occlusion_log_odds: float = param(
        1.5, "Log odds added to a stray when the track had missed the camera's previous frame but was seen by it "
        "within stray_occlusion_max_s: a person who comes out from behind another is more often someone else "
        "(chosen on development scenarios; 0 = off).", low=0.0, high=100.0)
    stray_occlusion_max_s: float = param(
        3.0, "How long a track unseen by a camera counts as hidden from it for stray_occlusion_log_odds; a "
        "longer gap is a person walking into that camera's view (s).", low=0.0, high=3600.0)

    def __post_init__(self) -> None:
        validate_fields(self)

    @property
    def gate_mahalanobis_sq(self) -> float:
        """Squared-Mahalanobis gate: chi-square quantile at ``gate_probability`` with 2 dof."""
        return float(chi2.ppf(self.gate_probability, df=2))

    @property
    def motion_model(self) -> ConstantVelocityModel:
        return ConstantVelocityModel(self.accel_noise_mps2, self.init_velocity_std_mps)
