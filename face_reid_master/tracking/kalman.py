"""Constant-velocity Kalman filter on the world ground plane, vectorised across tracks.

State per track is ``(x, y, vx, vy)`` in the world frame (metres, m/s); the measurement is the
``(x, y)`` ground position of a person detection.  The motion model is the *continuous* white-noise
acceleration model (filterpy's ``Q_continuous_white_noise``): unlike the piecewise (discrete) model,
predicting over ``a`` then ``b`` seconds gives exactly the same covariance as predicting over
``a + b``, which matters because frames from several unsynchronised cameras give irregular time steps.

The model is *defined* with filterpy (:meth:`ConstantVelocityModel.to_filterpy` builds the
equivalent ``filterpy.kalman.KalmanFilter``, and the tests check the two agree to 1e-12), but the hot
path runs in numpy on stacked ``(N, 4)`` / ``(N, 4, 4)`` arrays, all tracks at once (one filterpy
object per track is too slow for the per-frame budget; see bench/tracker_bench.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import KalmanFilter

from face_reid_camera.common.checks import check_real

__all__ = ["ConstantVelocityModel", "mahalanobis_sq"]

_H = np.eye(2, 4)
_EYE4 = np.eye(4)


@dataclass(frozen=True)
class ConstantVelocityModel:
    """Parameters of the per-person constant-velocity model (all tracks share them).

    ``accel_noise_mps2`` is the standard deviation of the white acceleration noise over one second:
    the spectral density is ``q = accel_noise_mps2**2`` (m^2/s^3), so an unobserved velocity
    random-walks with std ``accel_noise_mps2 * sqrt(dt)``.  ``init_velocity_std_mps`` is the prior
    velocity std of a new track (its position prior is the first detection's std).
    """

    accel_noise_mps2: float = 1.0
    init_velocity_std_mps: float = 1.0

    def __post_init__(self) -> None:
        for name in ("accel_noise_mps2", "init_velocity_std_mps"):
            check_real(name, getattr(self, name), 0.0, low_open=True)

    @property
    def spectral_density(self) -> float:
        """Acceleration noise spectral density q in m^2/s^3."""
        return float(self.accel_noise_mps2) ** 2

    # ------------------------------------------------------------------ batched numpy filter
    def initial_state(self, z: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """New-track states from first detections ``z`` (k, 2) with variances ``r2`` (k,).

        Position = detection, velocity = 0 with std ``init_velocity_std_mps``; returns (k, 4), (k, 4, 4).
        """
        k = z.shape[0]
        x = np.zeros((k, 4))
        x[:, :2] = z
        P = np.zeros((k, 4, 4))
        P[:, 0, 0] = r2
        P[:, 1, 1] = r2
        P[:, 2, 2] = P[:, 3, 3] = float(self.init_velocity_std_mps) ** 2
        return x, P

    def process_noise(self, dt: np.ndarray) -> np.ndarray:
        """Continuous white-acceleration noise Q(|dt|) stacked as (N, 4, 4).

        Same values as ``Q_continuous_white_noise(2, dt, q, block_size=2, order_by_dim=False)``;
        ``|dt|`` is used so that a backward prediction (retrodiction) also *adds* uncertainty.
        """
        a = np.abs(dt)
        q = self.spectral_density
        Q = np.zeros((a.shape[0], 4, 4))
        pp = q * a**3 / 3.0
        pv = q * a**2 / 2.0
        vv = q * a
        Q[:, 0, 0] = Q[:, 1, 1] = pp
        Q[:, 0, 2] = Q[:, 2, 0] = Q[:, 1, 3] = Q[:, 3, 1] = pv
        Q[:, 2, 2] = Q[:, 3, 3] = vv
        return Q

    def predict(self, x: np.ndarray, P: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predict states (N, 4) / covariances (N, 4, 4) by per-track time steps ``dt`` (N,) seconds.

        Returns new arrays (inputs untouched).  Negative ``dt`` is only used for gating a late
        detection against a track that was born after it; see ``tracker.py``.
        """
        x_new = x.copy()
        x_new[:, :2] += dt[:, None] * x[:, 2:]
        # F P F^T in block form (F = [[I, dt I], [0, I]]): rows then columns of P gain dt * velocity.
        a = dt[:, None, None]
        P_new = P.copy()
        P_new[:, :2, :] += a * P[:, 2:, :]
        P_new[:, :, :2] += a * P_new[:, :, 2:]
        adt = np.abs(dt)
        q = self.spectral_density
        pp, pv, vv = q * adt**3 / 3.0, q * adt**2 / 2.0, q * adt
        for i in (0, 1):  # + Q(|dt|), same entries as process_noise()
            P_new[:, i, i] += pp
            P_new[:, i, i + 2] += pv
            P_new[:, i + 2, i] += pv
            P_new[:, i + 2, i + 2] += vv
        return x_new, P_new

    @staticmethod
    def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Kalman update of (k, 4) / (k, 4, 4) priors with positions ``z`` (k, 2), variances ``r2`` (k,).

        Joseph-form covariance update, like filterpy; returns new arrays (inputs untouched).
        """
        k = x.shape[0]
        a = P[:, 0, 0] + r2
        b = P[:, 0, 1]
        d = P[:, 1, 1] + r2
        det = a * d - b * b
        S_inv = np.empty((k, 2, 2))
        S_inv[:, 0, 0] = d / det
        S_inv[:, 1, 1] = a / det
        S_inv[:, 0, 1] = S_inv[:, 1, 0] = -b / det
        K = P[:, :, :2] @ S_inv  # (k, 4, 2); P H^T = first two columns of P
        y = z - x[:, :2]
        x_new = x + (K @ y[:, :, None])[:, :, 0]
        I_KH = np.empty((k, 4, 4))
        I_KH[:] = _EYE4  # (np.tile costs several times as much for the few tracks of a frame)
        I_KH[:, :, :2] -= K
        P_new = I_KH @ P @ I_KH.transpose(0, 2, 1) + r2[:, None, None] * (K @ K.transpose(0, 2, 1))
        return x_new, P_new

    # ------------------------------------------------------------------ filterpy reference
    def to_filterpy(self, z: np.ndarray, position_std_m: float) -> KalmanFilter:
        """An equivalent single-track ``filterpy.kalman.KalmanFilter`` started at detection ``z``.

        This is the reference definition of the model; step it with :meth:`filterpy_predict` and
        ``kf.update(z, R=std**2 * np.eye(2))``.
        """
        kf = KalmanFilter(dim_x=4, dim_z=2)
        x, P = self.initial_state(np.asarray(z, dtype=float).reshape(1, 2), np.array([position_std_m**2]))
        kf.x = x[0].reshape(4, 1)
        kf.P = P[0]
        kf.H = _H.copy()
        kf.R = np.eye(2) * position_std_m**2
        return kf

    def filterpy_predict(self, kf: KalmanFilter, dt: float) -> None:
        """Predict a filterpy reference filter by ``dt`` seconds with this model's F and Q."""
        F = np.eye(4)
        F[0, 2] = F[1, 3] = dt
        kf.F = F
        kf.Q = Q_continuous_white_noise(
            dim=2, dt=dt, spectral_density=self.spectral_density, block_size=2, order_by_dim=False
        )
        kf.predict()


def mahalanobis_sq(
    z_pred: np.ndarray, P_pos: np.ndarray, z: np.ndarray, r2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Squared Mahalanobis distances (N, M) of detections ``z`` (M, 2) to predicted positions.

    ``z_pred`` (N, 2) and ``P_pos`` (N, 2, 2) are the tracks' predicted positions and position
    covariances; the innovation covariance of pair (i, j) is ``S = P_pos[i] + r2[j] * I``.  Also
    returns ``log det S`` (N, M), so that ``d2 + log det S`` is the pair's negative log-likelihood
    up to a constant.  The 2x2 inverse is done in closed form on the whole (N, M) grid at once.
    """
    a = P_pos[:, 0, 0][:, None] + r2[None, :]
    d = P_pos[:, 1, 1][:, None] + r2[None, :]
    b = 0.5 * (P_pos[:, 0, 1] + P_pos[:, 1, 0])[:, None]
    dx = z[None, :, 0] - z_pred[:, 0, None]
    dy = z[None, :, 1] - z_pred[:, 1, None]
    det = a * d - b * b
    return (d * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det, np.log(det)
