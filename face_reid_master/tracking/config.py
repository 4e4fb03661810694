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
    """Tracker parameters (metres, seconds), the ROS parameters ``tracker.*``; ValueError on bad values.

    ``accel_noise_mps2``: white-acceleration noise std over 1 s (spectral density = its square).
    ``init_velocity_std_mps``: velocity prior std of a new track.
    ``gate_probability``: detections outside the chi-square(2 dof) quantile of a track are not
    associated with it.
    ``detections_to_confirm`` hits within ``confirm_window_s`` of creation confirm a track; a
    tentative track not confirmed by then is deleted.
    ``lost_after_s``: a confirmed track without detection for this long becomes LOST; after
    ``delete_after_s`` more it is DELETED.
    ``max_detection_delay_s``: frames up to this much older than the newest accepted stamp are applied
    (exactly, see the tracker module doc); older ones are rejected.
    ``max_future_stamp_s``: frames further than this ahead of the newest stamp are rejected...
    ``clock_resync_frames``: ...unless this many consecutive frames are rejected in the same
    direction, which is taken as a clock jump (0 disables).
    ``max_gate_distance_m``: additional Euclidean gate around the predicted position (and cap of the
    second-pass reach), so that a coasting or LOST track, whose covariance grows to metres, cannot
    capture someone else (inf = off); a hidden person who reappears further off gets a new track,
    whose identity the face table restores.
    ``min_person_separation_m``: two people are assumed never closer than this.  A detection that
    fails every gate but lies this close to the predicted position of an unmatched track, or within
    ``min_person_separation_m + max_speed_mps * (time since its last detection)`` of that last
    detection, is associated with it in a second pass (turns and stops outrun the constant-velocity
    gate).  A leftover detection this close to any track or to another new detection starts no
    track (a person's detections that miss their own track's gate would otherwise spawn
    duplicates), and a tentative track this close to a confirmed one is deleted.
    ``coast_after_s``: a confirmed track not detected for this long is "coasting": it is offered
    detections only after the freshly detected tracks have had both association passes.
    ``camera_window_s``: a track's ``cameras`` are those that detected it within this window.
    ``max_tracks``: cap on live tracks (bounded latency under clutter); extra detections are dropped.
    Appearance (used only where a track and a detection both carry a body-appearance embedding, in the
    learned metric's units: 1 = the median distance between two different people): a pair farther apart
    than ``appearance_gate`` is clearly two people and never associated, however close in position;
    ``appearance_weight`` x the distance joins the association cost (``appearance_match_distance`` stands in
    for an unknown one); a LOST track takes back a detection beyond its position gates, within walking reach
    of its last detection, when they are nearer than ``appearance_match_distance``. A track keeps its newest
    ``appearance_gallery_size`` embeddings.
    """

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

    def __post_init__(self) -> None:
        validate_fields(self)

    @property
    def gate_mahalanobis_sq(self) -> float:
        """Squared-Mahalanobis gate: chi-square quantile at ``gate_probability`` with 2 dof."""
        return float(chi2.ppf(self.gate_probability, df=2))

    @property
    def motion_model(self) -> ConstantVelocityModel:
        return ConstantVelocityModel(self.accel_noise_mps2, self.init_velocity_std_mps)
