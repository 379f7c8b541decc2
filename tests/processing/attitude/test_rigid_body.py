"""Tests of processing.attitude.rigid_body (004 eqs. 1-5): torques, kinematics, the scalar RK4 integrator, frames."""

import math

import numpy as np
import pytest

from processing.attitude import rotations
from processing.attitude.rigid_body import (
    INERTIA_004_KG_M2,
    RigidBody004,
    dcm_BO_columns,
    dcm_OI_004,
    gravity_gradient_torque_B,
    magnetic_torque_B,
    measurement_model_B,
    omega_BO_B,
    q_OB_from_roll_pitch_yaw_004,
    rigid_body_derivative,
    roll_pitch_yaw_004,
    sun_direction_O_004,
)
from processing.frames.orbital import dcm_IO_lvlh_004
from processing.orbits.two_body import circular_orbit_state, mean_motion_rad_s
from processing.units import R_EARTH_M

J = np.diag(INERTIA_004_KG_M2)
W0 = float(mean_motion_rad_s(R_EARTH_M + 650e3))
RNG = np.random.default_rng(7)


def _random_q(n: int) -> np.ndarray:
    return rotations.quat_normalize(RNG.normal(size=(n, 4)))


def test_gravity_gradient_torque_closed_form() -> None:
    """004 eq. (2): 3 n^2 c3 x (J c3) with c3 the nadir in B; zero in the orbital orientation; a pitch
    (rotation about Y0) by theta gives -3 n^2 (Jx - Jz) sin(theta) cos(theta) about y (restoring)."""
    q = _random_q(5)
    c3 = np.array([dcm_BO_columns(tuple(qi))[2] for qi in q])
    np.testing.assert_allclose(gravity_gradient_torque_B(q, J, W0**2),
                               3 * W0**2 * np.cross(c3, c3 @ J.T), rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(gravity_gradient_torque_B([1, 0, 0, 0], J, W0**2), 0.0, atol=1e-20)
    th = 0.1
    tau = gravity_gradient_torque_B(rotations.quat_from_axis_angle([0, 1, 0], th), J, W0**2)
    np.testing.assert_allclose(tau, [0, -3 * W0**2 * (J[0, 0] - J[2, 2]) * np.sin(th) * np.cos(th), 0], atol=1e-15)


def test_magnetic_torque_and_measurement_model() -> None:
    mu, B = np.array([1.0, 2.0, 3.0]), np.array([2e-5, -1e-5, 3e-5])
    np.testing.assert_allclose(magnetic_torque_B(mu, B), np.cross(mu, B))
    q = _random_q(3)
    v_O = RNG.normal(size=(3, 3))
    np.testing.assert_allclose(measurement_model_B(q, v_O),
                               np.einsum("kji,kj->ki", rotations.quat_to_dcm(q), v_O), atol=1e-15)


def test_scalar_derivative_matches_vectorised_model() -> None:
    body = RigidBody004.from_inertia(INERTIA_004_KG_M2)
    q, w = _random_q(4), RNG.normal(size=(4, 3)) * 1e-3
    tau_B, mu, B_O = RNG.normal(size=3) * 1e-5, RNG.normal(size=3), RNG.normal(size=3) * 3e-5
    n2 = W0**2
    for qi, wi in zip(q, w, strict=True):
        dq, dw = body.derivative(tuple(qi), tuple(wi), W0, n2, tuple(tau_B), (1e-6, -2e-6, 0.0), tuple(mu), tuple(B_O))
        B_B = measurement_model_B(qi, B_O)
        torque = (gravity_gradient_torque_B(qi, J, n2) + tau_B + measurement_model_B(qi, [1e-6, -2e-6, 0.0])
                  + np.cross(mu, B_B))
        dq_v, dw_v = rigid_body_derivative(qi, wi, torque, J, [0.0, -W0, 0.0])
        np.testing.assert_allclose(dq, dq_v, atol=1e-15)
        np.testing.assert_allclose(dw, dw_v, atol=1e-15)
    np.testing.assert_allclose(omega_BO_B([0.0, -W0, 0.0], [1, 0, 0, 0], [0.0, -W0, 0.0]), 0.0, atol=1e-18)


def test_orbital_equilibrium_is_kept_and_rk4_converges() -> None:
    body = RigidBody004.from_inertia(J)
    q, w = (1.0, 0.0, 0.0, 0.0), (0.0, -W0, 0.0)
    for _ in range(100):
        q, w = body.rk4_step(q, w, 1.0, W0, W0**2)
    np.testing.assert_allclose(q, (1, 0, 0, 0), atol=1e-14)
    np.testing.assert_allclose(w, (0, -W0, 0), atol=1e-18)

    def run(dt: float) -> np.ndarray:
        qq, ww = tuple(q_OB_from_roll_pitch_yaw_004(0.3, -0.2, 0.5)), (1e-3, -W0, 2e-3)
        for _ in range(int(round(200 / dt))):
            qq, ww = body.rk4_step(qq, ww, dt, W0, W0**2, tau_B=(1e-5, 0, 0), mu_B=(1, 2, 3),
                                   B_O0=(2e-5, 1e-6, 3e-5), B_O1=(2e-5, 1e-6, 3e-5))
        return np.array(qq + ww)

    e1, e2 = np.abs(run(2.0) - run(0.5)).max(), np.abs(run(1.0) - run(0.5)).max()
    assert e2 < 1e-9 and e1 / e2 > 10  # 4th order: ~ (2^4 - 1) / (1 - 2^-4) = 17


def test_torque_free_motion_conserves_energy_and_momentum() -> None:
    """Without torques and with w0 = 0 the body's kinetic energy and |J w| are constant (RK4, 1 s steps)."""
    body = RigidBody004.from_inertia(J)
    q, w = tuple(rotations.quat_normalize([1.0, 0.2, -0.1, 0.3])), (0.01, -0.02, 0.05)
    e0, h0 = 0.5 * np.dot(w, J @ w), np.linalg.norm(J @ w)
    for _ in range(600):
        q, w = body.rk4_step(q, w, 0.5, 0.0, 0.0)
    assert 0.5 * np.dot(w, J @ w) == pytest.approx(e0, rel=1e-8)
    assert np.linalg.norm(J @ np.array(w)) == pytest.approx(h0, rel=1e-8)


def test_dcm_OI_004_matches_orbital_frame_and_sun_eq5() -> None:
    a, inc, raan, u0 = R_EARTH_M + 650e3, math.radians(98), 1.1, 0.3
    t = np.linspace(0, 5000, 20)
    r, v = circular_orbit_state(t, a, inc, raan, u0)
    u = u0 + mean_motion_rad_s(a) * t
    m = dcm_OI_004(u, inc, raan)
    np.testing.assert_allclose(m, np.swapaxes(dcm_IO_lvlh_004(r, v), -1, -2), atol=1e-12)
    s_I = np.array([0.3, -0.8, 0.52])
    s_I /= np.linalg.norm(s_I)
    np.testing.assert_allclose(sun_direction_O_004(u, inc, raan, s_I), m @ s_I, atol=1e-15)


def test_roll_pitch_yaw_round_trip_and_small_angles() -> None:
    roll, pitch, yaw = RNG.uniform(-1, 1, 20), RNG.uniform(-1.2, 1.2, 20), RNG.uniform(-3, 3, 20)
    q = q_OB_from_roll_pitch_yaw_004(roll, pitch, yaw)
    np.testing.assert_allclose(np.stack(roll_pitch_yaw_004(q)), np.stack([roll, pitch, yaw]), atol=1e-12)
    # small angles: the rotation vector of q_OB is (roll, pitch, yaw) to first order
    np.testing.assert_allclose(rotations.quat_to_rotvec(q_OB_from_roll_pitch_yaw_004(1e-4, -2e-4, 3e-4)),
                               [1e-4, -2e-4, 3e-4], atol=1e-7)  # second order: ~angle^2
    # yaw alone is a rotation about Z0 (nadir): dcm_BO maps the O x axis to (cos, -sin, 0) in B
    np.testing.assert_allclose(measurement_model_B(q_OB_from_roll_pitch_yaw_004(0, 0, 0.5), [1, 0, 0]),
                               [np.cos(0.5), -np.sin(0.5), 0], atol=1e-15)


def test_bad_inertia_rejected() -> None:
    with pytest.raises(ValueError, match="principal body axes"):
        RigidBody004.from_inertia([[1, 0.1, 0], [0.1, 1, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match=r"got shape \(2,\)"):
        RigidBody004.from_inertia([1.0, 2.0])
