"""Tests of processing.gyroless.ekf (004's EKF and the MEKF), processing.gyroless.rts_smoother and
processing.estimation.consistency on open-loop synthetic truth (fast; the closed loop is in test_seed004)."""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from processing.attitude import rotations
from processing.attitude.rigid_body import INERTIA_004_KG_M2, RigidBody004, q_OB_from_roll_pitch_yaw_004
from processing.estimation.consistency import chi_square_stats, nees, whiteness
from processing.gyroless.ekf import FilterTuning
from processing.gyroless.ekf004 import GyrolessEKF, dcm_v_dq
from processing.gyroless.filtering import (
    GyrolessInputs,
    attitude_errors_rad,
    initial_covariance,
    run_filter,
    triad_q_OB,
)
from processing.gyroless.mekf import GyrolessMEKF
from processing.gyroless.rts_smoother import rts_smooth
from processing.orbits.two_body import mean_motion_rad_s
from processing.units import R_EARTH_M

J = INERTIA_004_KG_M2
W0 = float(mean_motion_rad_s(R_EARTH_M + 650e3))
N2 = W0**2


def test_dcm_v_dq_is_the_derivative() -> None:
    rng = np.random.default_rng(1)
    q, v = rng.normal(size=4), rng.normal(size=3)

    def f(qq: np.ndarray) -> np.ndarray:  # homogeneous form (q0^2 - u.u) v + 2 (u.v) u - 2 q0 u x v
        u = qq[1:]
        return (qq[0] ** 2 - u @ u) * v + 2 * (u @ v) * u - 2 * qq[0] * np.cross(u, v)

    num = np.column_stack([(f(q + e) - f(q - e)) / 2e-6 for e in np.eye(4) * 1e-6])
    np.testing.assert_allclose(np.array(dcm_v_dq(tuple(q), tuple(v))), num, atol=1e-8)
    qn = q / np.linalg.norm(q)
    np.testing.assert_allclose(f(qn), rotations.quat_rotate(rotations.quat_conjugate(qn), v), atol=1e-14)


def _fvec(body: RigidBody004, x: np.ndarray, tb: tuple) -> np.ndarray:
    dq, dw = body.derivative(tuple(x[3:7]), tuple(x[0:3]), W0, N2, tb, (x[7], x[8], 0.0), (0, 0, 0), (0, 0, 0))
    return np.array([*dw, *dq, 0.0, 0.0])


def test_ekf_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(2)
    q = rotations.quat_normalize(rng.normal(size=4))
    f = GyrolessEKF(J, q, rng.normal(size=3) * 1e-3, np.eye(9), tau_d_O=(3e-6, -5e-6))
    F, x0, body, tb = f.jacobian(W0, N2), f.state(), RigidBody004.from_inertia(J), (1e-5, 2e-5, -1e-5)
    for _ in range(4):
        d = rng.normal(size=9)
        d[3:7] -= (d[3:7] @ x0[3:7]) * x0[3:7]  # tangent to the unit sphere
        num = (_fvec(body, x0 + 1e-7 * d, tb) - _fvec(body, x0 - 1e-7 * d, tb)) / 2e-7
        np.testing.assert_allclose(F @ d, num, atol=1e-11)


def test_mekf_error_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(3)
    q = rotations.quat_normalize(rng.normal(size=4))
    f = GyrolessMEKF(J, q, rng.normal(size=3) * 1e-3, np.eye(8), tau_d_O=(3e-6, -5e-6))
    F, x0, dt = f.jacobian(W0, N2), f.state(), 1e-3

    def step(x: np.ndarray) -> np.ndarray:
        g = GyrolessMEKF(J, x[3:7], x[0:3], np.eye(8), tau_d_O=x[7:9])
        g._propagate_state(dt, W0, N2, np.array([1e-5, 2e-5, -1e-5]))
        return g.state()

    xn, num = step(x0), np.zeros((8, 8))
    for i, e in enumerate(np.eye(8) * 1e-6):
        num[:, i] = (GyrolessMEKF.error_between(step(GyrolessMEKF.apply_error(x0, e)), xn)
                     - GyrolessMEKF.error_between(step(GyrolessMEKF.apply_error(x0, -e)), xn)) / 2e-6
    np.testing.assert_allclose(num, expm(F * dt), atol=2e-9)


def test_error_coordinates_round_trip() -> None:
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.normal(size=3), rotations.quat_normalize(rng.normal(size=4)), rng.normal(size=2)])
    for cls, n in ((GyrolessMEKF, 8), (GyrolessEKF, 9)):
        dx = rng.normal(size=n) * 1e-2
        if cls is GyrolessEKF:
            dx[3:7] -= (dx[3:7] @ x[3:7]) * x[3:7]
        y = cls.apply_error(x, dx)
        np.testing.assert_allclose(cls.error_between(y, x), dx, atol=1e-4 if cls is GyrolessEKF else 1e-12)
        assert np.linalg.norm(y[3:7]) == pytest.approx(1.0)


def test_triad_is_exact_on_noise_free_vectors() -> None:
    q = q_OB_from_roll_pitch_yaw_004(0.4, -0.3, 1.2)
    b_O, s_O = np.array([0.3, 0.2, -0.9]), np.array([0.1, 0.95, 0.2])
    b_B, s_B = (rotations.quat_rotate(rotations.quat_conjugate(q), v) for v in (b_O, s_O))
    assert rotations.angle_between(triad_q_OB(b_O, s_O, b_B, s_B), q) < 1e-12


@pytest.fixture(scope="module")
def open_loop() -> dict:
    """One hour of torque-free-but-gravity-gradient motion with noisy unit-vector measurements at 1 Hz."""
    rng = np.random.default_rng(5)
    K = 3600
    body = RigidBody004.from_inertia(J)
    q, w = tuple(q_OB_from_roll_pitch_yaw_004(0.05, -0.04, 0.1)), (2e-4, -W0 + 1e-4, -3e-4)
    qs, ws = np.empty((K, 4)), np.empty((K, 3))
    for k in range(K):
        qs[k], ws[k] = q, w
        q, w = body.rk4_step(q, w, 1.0, W0, N2)
    t = np.arange(K, dtype=float)
    b_O = np.column_stack([np.cos(2 * W0 * t), 0.1 * np.ones(K), np.sin(2 * W0 * t)])
    b_O /= np.linalg.norm(b_O, axis=1, keepdims=True)
    s_O = np.tile([0.0, 1.0, 0.0], (K, 1))
    sb, ss = 3e-3, math.radians(0.5)

    def measure(v_O: np.ndarray, sigma: float) -> np.ndarray:
        v = rotations.quat_rotate(rotations.quat_conjugate(qs), v_O)
        n = rng.normal(size=v.shape) * sigma
        n -= np.sum(n * v, axis=1, keepdims=True) * v
        v = v + n
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    s_B = measure(s_O, ss)
    s_B[1200:2200] = np.nan  # a 1000 s sun outage
    inputs = GyrolessInputs(t_s=t, b_O=b_O, b_B=measure(b_O, sb), sigma_b_rad=np.full(K, sb), s_O=s_O, s_B=s_B,
                            sigma_s_rad=np.full(K, ss), torque_B_N_m=np.zeros((K, 3)), w0_rad_s=np.full(K, W0),
                            n2_rad2_s2=np.full(K, N2))
    tuning = FilterTuning(torque_noise_psd_N2_m2_s=(2e-7) ** 2, disturbance_walk_psd_N2_m2_s=(1e-9) ** 2)
    runs = {kind: run_filter(kind, inputs, J, [1, 0, 0, 0], [0, -W0, 0], tuning=tuning) for kind in ("ekf", "mekf")}
    return {"q": qs, "w": ws, "inputs": inputs, "runs": runs, "smoothed": {k: rts_smooth(r) for k, r in runs.items()}}


@pytest.mark.parametrize("kind", ["ekf", "mekf"])
def test_filters_converge_from_a_wrong_start_and_the_smoother_improves(open_loop: dict, kind: str) -> None:
    run, sm = open_loop["runs"][kind], open_loop["smoothed"][kind]
    err_f = np.degrees(attitude_errors_rad(run.q_OB, open_loop["q"]))
    err_s = np.degrees(attitude_errors_rad(sm.q_OB, open_loop["q"]))
    assert np.degrees(rotations.angle_between(run.x_pred[0, 3:7], open_loop["q"][0])) > 5.0  # started ~7 deg off
    late = slice(600, None)
    rms_f, rms_s = np.sqrt(np.mean(err_f[late] ** 2, axis=0)), np.sqrt(np.mean(err_s[late] ** 2, axis=0))
    assert np.all(rms_f < 0.2) and np.all(rms_s < rms_f) and np.all(rms_s < 0.1)
    np.testing.assert_allclose(sm.x[-1], run.x_filt[-1])
    assert np.all(sm.attitude_sigma_rad[late] <= run.attitude_sigma_rad[late] * (1 + 1e-6))
    # rate estimate
    w_err = np.abs(sm.omega_BI_B[late] - open_loop["w"][late]).max(axis=0)
    assert np.all(w_err < 2e-5)
    # degradation in the sun outage (steps 1200-2200) is visible in the covariance and bounded
    sig = np.degrees(run.attitude_sigma_rad.max(axis=1))
    assert sig[2150] > 1.5 * sig[1150] and sig[2150] < 1.0
    assert np.abs(err_f[1200:2200]).max() < 1.0


def test_mekf_consistency_nis_nees_whiteness(open_loop: dict) -> None:
    run = open_loop["runs"]["mekf"]
    late = slice(600, None)
    ns = chi_square_stats(run.nis[late], run.nis_dof[late])
    assert ns.mean_dof == pytest.approx(4 - 2 * 1000 / 3000, rel=1e-2)
    assert 0.92 < ns.fraction_in_95 < 0.98 and abs(ns.mean / ns.mean_dof - 1) < 0.05
    e = attitude_errors_rad(run.q_OB, open_loop["q"])
    ne = chi_square_stats(nees(e[late], run.P_filt[late, 0:3, 0:3]), 3)
    assert 0.85 < ne.fraction_in_95 and 1.5 < ne.mean < 4.5
    wh = whiteness(run.whitened[late, :4])
    assert wh.fraction_outside < 0.15


def test_consistency_helpers_on_known_sequences() -> None:
    rng = np.random.default_rng(6)
    x = rng.chisquare(4, 5000)
    st = chi_square_stats(x, 4)
    assert st.mean_in_bounds and 0.93 < st.fraction_in_95 < 0.97
    assert not chi_square_stats(2 * x, 4).mean_in_bounds
    assert whiteness(rng.normal(size=(5000, 2))).fraction_outside < 0.15
    ar = np.zeros(5000)
    for k in range(1, 5000):
        ar[k] = 0.8 * ar[k - 1] + rng.normal()
    w = whiteness(ar)
    assert w.fraction_outside > 0.5 and w.rho[0, 0] == pytest.approx(0.8, abs=0.05)
    P = np.broadcast_to(np.diag([4.0, 1.0]), (3, 2, 2))
    np.testing.assert_allclose(nees(np.array([[2.0, 0], [0, 1], [2, 1]]), P), [1, 1, 2])


def test_bad_inputs_are_rejected() -> None:
    with pytest.raises(ValueError, match=r"b_O must have shape \(2, 3\)"):
        GyrolessInputs(t_s=np.arange(2.0), b_O=np.zeros((3, 3)), b_B=np.zeros((2, 3)), sigma_b_rad=np.ones(2),
                       s_O=np.zeros((2, 3)), s_B=np.zeros((2, 3)), sigma_s_rad=np.ones(2),
                       torque_B_N_m=np.zeros((2, 3)), w0_rad_s=np.ones(2), n2_rad2_s2=np.ones(2))
    with pytest.raises(ValueError, match=r"P0 must be \(8, 8\)"):
        GyrolessMEKF(J, [1, 0, 0, 0], [0, 0, 0], np.eye(9))
    with pytest.raises(ValueError, match="kind must be one of"):
        run_filter("ukf", None, J, [1, 0, 0, 0], [0, 0, 0])  # type: ignore[arg-type]
    assert initial_covariance("ekf", [1, 0, 0, 0], 0.1, 1e-3, 1e-5).shape == (9, 9)
