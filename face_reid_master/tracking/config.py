"""Tracker parameters (the ROS parameters ``tracker.*``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.stats import chi2

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.tracking.kalman import ConstantVelocityModel

__all__ = ["TrackerConfig"]

_POSITIVE = ("accel_noise_mps2", "init_velocity_std_mps", "confirm_window_s", "lost_after_s")
_NON_NEGATIVE = (
    "delete_after_s",
    "max_detection_delay_s",
    "max_future_stamp_s",
    "camera_window_s",
    "min_person_separation_m",
    "max_speed_mps",
    "coast_after_s",
)


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker parameters (metres, seconds).  Validated on construction; ValueError on bad values.

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
    """

    accel_noise_mps2: float = 1.0
    init_velocity_std_mps: float = 1.0
    gate_probability: float = 0.99
    detections_to_confirm: int = 3
    confirm_window_s: float = 1.0
    lost_after_s: float = 1.0
    delete_after_s: float = 3.0
    max_detection_delay_s: float = 0.3
    max_future_stamp_s: float = 2.0
    clock_resync_frames: int = 5
    max_gate_distance_m: float = 1.0
    min_person_separation_m: float = 0.4
    max_speed_mps: float = 2.0
    coast_after_s: float = 0.25
    camera_window_s: float = 0.5
    max_tracks: int = 200

    def __post_init__(self) -> None:
        for name in _POSITIVE:
            check_real(name, getattr(self, name), 0.0, low_open=True)
        for name in _NON_NEGATIVE:
            check_real(name, getattr(self, name), 0.0)
        check_real("gate_probability", self.gate_probability, 0.0, 1.0, low_open=True, high_open=True)
        check_real("max_gate_distance_m", self.max_gate_distance_m, 0.0, math.inf, low_open=True, allow_inf=True)
        check_int("detections_to_confirm", self.detections_to_confirm, 1)
        check_int("clock_resync_frames", self.clock_resync_frames, 0)
        check_int("max_tracks", self.max_tracks, 1)

    @property
    def gate_mahalanobis_sq(self) -> float:
        """Squared-Mahalanobis gate: chi-square quantile at ``gate_probability`` with 2 dof."""
        return float(chi2.ppf(self.gate_probability, df=2))

    @property
    def motion_model(self) -> ConstantVelocityModel:
        return ConstantVelocityModel(self.accel_noise_mps2, self.init_velocity_std_mps)
