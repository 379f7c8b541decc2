"""Tests of processing.gyroless.magnetic_control: energy law (004 eq. 6) and averaged LQR (004 eq. 7)."""

import numpy as np
import pytest

from processing.attitude.rigid_body import INERTIA_004_KG_M2, q_OB_from_roll_pitch_yaw_004
from processing.environment import dipole_field_O004_nT
from processing.gyroless.magnetic_control import (
    design_averaged_lqr,
    energy_law_dipole,
    linearised_model_004,
    lqr_dipole,
    lqr_state,
    saturate_dipole,
)
from processing.orbits.two_body import mean_motion_rad_s
from processing.units import R_EARTH_M

J = np.array(INERTIA_004_KG_M2)
A_M = R_EARTH_M + 650e3
W0 = float(mean_motion_rad_s(A_M))
RNG = np.random.default_rng(11)


def _orbit_field_T() -> np.ndarray:
    u = np.linspace(0, 2 * np.pi, 600, endpoint=False)
    return dipole_field_O004_nT(A_M, np.radians(98.0), u) * 1e-9


def test_energy_law_torque_is_dissipative_and_restoring() -> None:
    B = RNG.normal(size=(50, 3)) * 3e-5
    w = RNG.normal(size=(50, 3)) * 1e-3
    mu = energy_law_dipole(np.array([1.0, 0, 0, 0]), w, B)
    tau = np.cross(mu, B)
    assert np.all(np.einsum("ki,ki->k", tau, w) <= 1e-30)  # tau . w_BO = -beta |B x w|^2
    np.testing.assert_allclose(np.einsum("ki,ki->k", mu, B), 0.0, atol=1e-12)  # mu perpendicular to B
    q = q_OB_from_roll_pitch_yaw_004(0.1, -0.05, 0.2)
    tau = np.cross(energy_law_dipole(q, np.zeros(3), B), B)
    assert np.all(np.einsum("ki,i->k", tau, q[1:]) <= 1e-30)  # restoring: tau . eps <= 0
    # sign-invariant in q (q and -q are the same attitude)
    np.testing.assert_allclose(energy_law_dipole(-q, w, B), energy_law_dipole(q, w, B))


def test_lqr_dipole_gives_the_projected_torque() -> None:
    """mu = (mu~ x B)/|B|  =>  tau = mu x B = -|B| (I - b b^T) mu~ (004, eq. 7)."""
    lqr = design_averaged_lqr(J, W0, _orbit_field_T())
    q, w = q_OB_from_roll_pitch_yaw_004(0.02, -0.01, 0.03), np.array([1e-4, -2e-4, 3e-4])
    B = np.array([2e-5, 5e-6, -3e-5])
    mu = lqr_dipole(lqr, q, w, B)
    u = -lqr.K @ lqr_state(q, w)
    b = B / np.linalg.norm(B)
    np.testing.assert_allclose(np.cross(mu, B), -np.linalg.norm(B) * (np.eye(3) - np.outer(b, b)) @ u, atol=1e-18)


def test_linearised_model_matches_the_classical_equations() -> None:
    """Gravity-gradient libration about the 004 orbital frame (e.g. Wertz 1978, §18.3; Sidi 1997, §7.3):
    pitch theta'' = -3 w0^2 (Jx - Jz)/Jy theta; roll phi'' = -4 w0^2 (Jy - Jz)/Jx phi + w0 (Jx + Jz - Jy)/Jx psi';
    yaw psi'' = -w0^2 (Jy - Jx)/Jz psi - w0 (Jx + Jz - Jy)/Jz phi'."""
    A, B = linearised_model_004(J, W0)
    jx, jy, jz = J
    expected = np.zeros((6, 6))
    expected[0, 1] = expected[2, 3] = expected[4, 5] = 1.0
    expected[1, 0] = -4 * W0**2 * (jy - jz) / jx
    expected[1, 5] = W0 * (jx + jz - jy) / jx
    expected[3, 2] = -3 * W0**2 * (jx - jz) / jy
    expected[5, 4] = -(W0**2) * (jy - jx) / jz
    expected[5, 1] = -W0 * (jx + jz - jy) / jz
    np.testing.assert_allclose(A, expected, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(B[[1, 3, 5]], np.diag(1 / J))


def test_averaged_lqr_solves_the_riccati_equation_and_stabilises() -> None:
    lqr = design_averaged_lqr(J, W0, _orbit_field_T())
    Phi, G, P = lqr.Phi, lqr.Gamma_bar, lqr.P
    Q, R = (0.1 * np.pi / 180) ** -2 * np.eye(6), np.diag([100.0, 100.0, 0.1])
    residual = Phi.T @ P @ Phi - P - Phi.T @ P @ G @ np.linalg.solve(G.T @ P @ G + R, G.T @ P @ Phi) + Q
    assert np.abs(residual).max() < 1e-6 * np.abs(P).max()
    assert lqr.spectral_radius < 1.0
    # the time-varying loop over one orbit (Floquet multipliers of the periodic dipole field) is stable
    from scipy.linalg import expm

    A, Bt = linearised_model_004(J, W0)
    M = np.zeros((9, 9))
    M[:6, :6], M[:6, 6:] = A, Bt
    E = expm(M * 1.0)
    Bf = dipole_field_O004_nT(A_M, np.radians(98.0), np.linspace(0, 2 * np.pi, 5863, endpoint=False)) * 1e-9
    mono = np.eye(6)
    for b in Bf:
        n = np.linalg.norm(b)
        mono = (E[:6, :6] - E[:6, 6:] @ (-n * (np.eye(3) - np.outer(b, b) / n**2)) @ lqr.K) @ mono
    assert np.abs(np.linalg.eigvals(mono)).max() < 1.0


def test_saturation_keeps_direction() -> None:
    mu = np.array([[3.0, -6.0, 1.5], [0.1, 0.2, 0.3]])
    out = saturate_dipole(mu, 3.0)
    np.testing.assert_allclose(out[0], mu[0] / 2)
    np.testing.assert_allclose(out[1], mu[1])
    assert saturate_dipole(mu, None) is not None and np.all(saturate_dipole(mu, None) == mu)
    with pytest.raises(ValueError, match=r"B_O_T must have shape \(N, 3\)"):
        design_averaged_lqr(J, W0, np.zeros(3))
