"""The constant-velocity Kalman model (tracking.kalman) against filterpy's reference ``KalmanFilter``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise

from face_reid_master.tracking.kalman import ConstantVelocityModel, mahalanobis_sq


def test_vectorised_filter_matches_filterpy_reference() -> None:
    model = ConstantVelocityModel(accel_noise_mps2=0.8, init_velocity_std_mps=1.3)
    rng = np.random.default_rng(0)
    stds = np.array([0.05, 0.1, 0.2])
    z0 = rng.normal(size=(3, 2))
    refs = [model.to_filterpy(z0[k], stds[k]) for k in range(3)]
    x, P = model.initial_state(z0, stds**2)
    for _ in range(30):
        dt = rng.uniform(0.0, 0.3, size=3)  # irregular, per track
        z = rng.normal(size=(3, 2))
        x, P = model.predict(x, P, dt)
        x, P = model.update(x, P, z, stds**2)
        for k, kf in enumerate(refs):
            model.filterpy_predict(kf, float(dt[k]))
            kf.update(z[k], R=stds[k] ** 2 * np.eye(2))
            np.testing.assert_allclose(x[k], kf.x.ravel(), rtol=0, atol=1e-12)
            np.testing.assert_allclose(P[k], kf.P, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dt", [0.0, 0.01, 1 / 30, 0.5, 3.0])
def test_process_noise_is_filterpys_continuous_white_noise(dt: float) -> None:
    model = ConstantVelocityModel(accel_noise_mps2=1.7)
    expected = Q_continuous_white_noise(2, dt, 1.7**2, block_size=2, order_by_dim=False)
    np.testing.assert_allclose(model.process_noise(np.array([dt]))[0], expected, atol=1e-15)


def test_prediction_composes_over_irregular_steps() -> None:
    # Continuous white-noise acceleration: predicting a then b equals predicting a + b, so the
    # irregular frame interleaving of several cameras does not change the motion model.
    model = ConstantVelocityModel(1.0)
    x, P = model.initial_state(np.array([[1.0, 2.0]]), np.array([0.01]))
    x[0, 2:] = [0.7, -0.4]
    xa, Pa = model.predict(*model.predict(x, P, np.array([0.013])), np.array([0.087]))
    xb, Pb = model.predict(x, P, np.array([0.1]))
    np.testing.assert_allclose(xa, xb, atol=1e-14)
    np.testing.assert_allclose(Pa, Pb, atol=1e-14)


def test_mahalanobis_and_log_det_match_dense_linear_algebra() -> None:
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 2, 2))
    P_pos = A @ A.transpose(0, 2, 1) * 0.1 + 0.01 * np.eye(2)
    z_pred = rng.normal(size=(5, 2))
    z = rng.normal(size=(4, 2))
    r2 = rng.uniform(0.001, 0.05, size=4)
    d2, log_det = mahalanobis_sq(z_pred, P_pos, z, r2)
    for i in range(5):
        for j in range(4):
            S = P_pos[i] + r2[j] * np.eye(2)
            y = z[j] - z_pred[i]
            assert d2[i, j] == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-10)
            assert log_det[i, j] == pytest.approx(np.log(np.linalg.det(S)), rel=1e-10)


@pytest.mark.parametrize(
    "kwargs", [{"accel_noise_mps2": 0.0}, {"init_velocity_std_mps": -1.0}, {"accel_noise_mps2": math.nan}]
)
def test_model_rejects_bad_parameters(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        ConstantVelocityModel(**kwargs)
