"""Magnetometer calibration by |B| matching (processing.magnetometer): the error model against an independent
construction, coverage of the 3-sigma intervals over many noise seeds (with injected bias, scale factors,
non-orthogonality and coupling), clean data (no warning condition, estimates consistent with zero, false-alarm
rate), short arcs and a constant field direction (not observable), correlated residuals and outliers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from processing.environment.igrf import igrf_field_E_nT
from processing.magnetometer.calibration import (
    CalibrationSettings,
    MagnetometerCalibrationError,
    calibrate_magnetometer,
    long_run_variance_factor,
)
from processing.magnetometer.model import MagnetometerErrors, d_matrix
from processing.simulate.seed004 import orbit_period_s, simulate_seed004
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
DECIMATE = 5  # 0.2 Hz: fast, still all 9 parameters determined over 3 orbits
NOISE_NT = 100.0
ERRORS = MagnetometerErrors.from_components([300.0, -200.0, 150.0], [0.02, -0.01, 0.015], [0.005, -0.003, 0.004])
COUPLING = np.array([[50.0, 10.0, 0.0], [0.0, -30.0, 5.0], [8.0, 0.0, 40.0]])


def _truth_vector(e: MagnetometerErrors, coupling: bool = False) -> np.ndarray:
    p = np.concatenate([e.bias_nT, e.scale_factor_errors, e.non_orthogonality_rad])
    return np.concatenate([p, e.coupling_nT_per_A_m2.ravel()]) if coupling else p


@pytest.fixture(scope="module")
def arc() -> dict[str, np.ndarray]:
    """Three orbits of the 004 spacecraft librating without control (gravity gradient + 004 disturbance),
    noise-free magnetometer (each test draws its own noise), IGRF |B| along the true orbit, 0.2 Hz."""
    sc = simulate_seed004(start_tai_ns=T0, duration_s=3 * orbit_period_s(), seed=1, controller="none",
                          estimator="truth", magnetometer_noise_nT=0.0)
    m = sc.streams["magnetometer"]
    B = np.column_stack([m["bx"], m["by"], m["bz"]])[::DECIMATE]
    ref = np.linalg.norm(igrf_field_E_nT(sc.truth.r_E[::DECIMATE], sc.truth.time_tai_ns[::DECIMATE]), axis=1)
    rng = np.random.default_rng(99)  # a duty-cycled dipole: each axis +-5 A m^2 or off, switched every 60 s
    n_blocks = B.shape[0] // 12 + 1
    mu = np.repeat(rng.choice([-5.0, 0.0, 5.0], size=(n_blocks, 3)), 12, axis=0)[: B.shape[0]]
    return {"B": B, "ref": ref, "mu": mu}


def test_model_against_an_independent_construction() -> None:
    rng = np.random.default_rng(0)
    B = rng.normal(size=(50, 3)) * 3e4
    mu = rng.normal(size=(50, 3))
    e = MagnetometerErrors.from_components([1.0, 2.0, 3.0], [0.01, 0.02, -0.03], [0.001, 0.002, 0.003], COUPLING)
    D = np.array([[0.01, 0.001, 0.002], [0.001, 0.02, 0.003], [0.002, 0.003, -0.03]])
    assert np.array_equal(d_matrix([0.01, 0.02, -0.03], [0.001, 0.002, 0.003]), D)
    expected = np.einsum("ij,kj->ki", np.eye(3) + D, B) + [1.0, 2.0, 3.0] + np.einsum("ij,kj->ki", COUPLING, mu)
    assert np.allclose(e.measure(B, mu), expected, rtol=0, atol=1e-9)
    assert np.allclose(e.correct(e.measure(B, mu), mu), B, rtol=0, atol=1e-9)
    # a rotation of the sensor does not change |B|: the reason only a symmetric D is estimable
    R = Rotation.from_rotvec([0.01, -0.02, 0.03]).as_matrix()
    assert np.allclose(np.linalg.norm(B @ R.T, axis=1), np.linalg.norm(B, axis=1))
    with pytest.raises(ValueError, match="shape"):
        MagnetometerErrors.from_components([1.0, 2.0])


def test_coverage_of_the_injected_errors_over_seeds(arc) -> None:  # noqa: ANN001
    B, ref = arc["B"], arc["ref"]
    truth = _truth_vector(ERRORS)
    rng = np.random.default_rng(2026)
    z, alarms = [], 0
    for _ in range(60):
        H = ERRORS.measure(B) + rng.normal(size=B.shape) * NOISE_NT
        c = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE,
                                   settings=CalibrationSettings(magnetometer_noise_nT=NOISE_NT))
        assert c.complete and c.observable.all()
        z.append((c.estimate - truth) / c.sigma)
        alarms += bool(c.inflation > 1 or c.chi2[2] < 1e-3 or not c.used.all())
    z = np.array(z)
    coverage = np.mean(np.abs(z) < 3.0)
    assert coverage > 0.98  # 3 sigma: 99.7 % expected
    assert np.all(np.abs(z.mean(axis=0)) < 0.5)  # no bias (the errors-in-variables term is corrected)
    assert np.all((z.std(axis=0) > 0.7) & (z.std(axis=0) < 1.3))  # sigma neither too small nor too large
    assert alarms <= 2
    # the residual |B| falls from the error level to the noise
    assert np.sqrt(np.mean(c.residual_before_nT**2)) > 3 * NOISE_NT
    assert abs(c.residual_sigma_nT / NOISE_NT - 1) < 0.05


def test_coverage_with_magnetorquer_coupling(arc) -> None:  # noqa: ANN001
    B, ref, mu = arc["B"], arc["ref"], arc["mu"]
    e = MagnetometerErrors(ERRORS.bias_nT, ERRORS.D, COUPLING)
    truth = _truth_vector(e, coupling=True)
    rng = np.random.default_rng(7)
    z = []
    for _ in range(20):
        H = e.measure(B, mu) + rng.normal(size=B.shape) * NOISE_NT
        c = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE, mu_B_A_m2=mu,
                                   settings=CalibrationSettings(estimate_coupling=True))
        assert c.complete
        z.append((c.estimate - truth) / c.sigma)
    z = np.array(z)
    assert np.mean(np.abs(z) < 3.0) > 0.98
    assert np.all(np.abs(z.mean(axis=0)) < 0.8)
    # without the coupling term the same data leave a larger residual
    c0 = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE)
    assert c0.residual_sigma_nT > 1.2 * c.residual_sigma_nT


def test_clean_data_consistent_with_zero_and_no_alarm(arc) -> None:  # noqa: ANN001
    B, ref = arc["B"], arc["ref"]
    rng = np.random.default_rng(11)
    z, alarms = [], 0
    for _ in range(40):
        c = calibrate_magnetometer(B + rng.normal(size=B.shape) * NOISE_NT, ref, sample_period_s=DECIMATE,
                                   settings=CalibrationSettings(magnetometer_noise_nT=NOISE_NT))
        z.append(c.estimate / c.sigma)
        alarms += bool(c.inflation > 1 or c.chi2[2] < 1e-3 or not c.used.all() or not c.complete)
    assert alarms <= 1  # expected rate ~0.2 % (two tests at 1e-3)
    assert np.mean(np.abs(np.array(z)) < 3.0) > 0.98


@pytest.mark.parametrize("seconds", [300.0, 900.0])
def test_short_arc_is_not_observable(arc, seconds: float) -> None:  # noqa: ANN001
    n = int(seconds / DECIMATE)
    B, ref = arc["B"][:n], arc["ref"][:n]
    H = ERRORS.measure(B) + np.random.default_rng(3).normal(size=B.shape) * NOISE_NT
    c = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE)
    assert not c.complete
    assert not c.observable.all()
    assert np.all(c.sigma[~c.observable] > CalibrationSettings().tolerances(9)[~c.observable])
    assert np.all(c.errors.D[np.diag(~c.observable[3:6])] == 0)  # unobservable values are not used


def test_constant_field_direction_is_not_observable(arc) -> None:  # noqa: ANN001
    """|B| varies along the orbit but the direction in the sensor frame is fixed: only the field along that
    direction is seen (bias and scale along u), so most of the 9 are undetermined."""
    ref = arc["ref"]
    u = np.array([0.6, 0.0, 0.8])
    H = ERRORS.measure(ref[:, None] * u) + np.random.default_rng(5).normal(size=(ref.size, 3)) * NOISE_NT
    c = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE)
    assert not c.complete
    assert np.sum(~c.observable) >= 6
    assert c.singular_values[-1] < 1e-6  # the information matrix is (nearly) singular


def test_correlated_field_model_error_inflates_the_sigma(arc) -> None:  # noqa: ANN001
    """A slowly varying field-model error (AR(1), 30 nT, 10 min) on top of white noise: the whiteness test
    fails and the covariance is inflated (the honest sigma covers the error)."""
    B, ref = arc["B"], arc["ref"]
    rng = np.random.default_rng(8)
    phi = np.exp(-DECIMATE / 600.0)
    walk = np.zeros(ref.size)
    kick = rng.normal(size=ref.size) * 30.0 * np.sqrt(1 - phi**2)
    for k in range(1, ref.size):  # sequential AR(1) recursion
        walk[k] = phi * walk[k - 1] + kick[k]
    H = ERRORS.measure(B * (1 + walk / ref)[:, None]) + rng.normal(size=B.shape) * 20.0
    c = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE)
    assert c.whiteness_p < 1e-3 and c.inflation > 2.0
    z = (c.estimate - _truth_vector(ERRORS)) / c.sigma
    assert np.all(np.abs(z) < 4.0)
    assert long_run_variance_factor(rng.normal(size=5000), 100) < 1.3


def test_outliers_are_rejected(arc) -> None:  # noqa: ANN001
    B, ref = arc["B"], arc["ref"]
    rng = np.random.default_rng(4)
    H = ERRORS.measure(B) + rng.normal(size=B.shape) * NOISE_NT
    bad = rng.choice(ref.size, 15, replace=False)
    H[bad] *= 1.15  # +15 % of |B| (a spike across the field would hardly change |B|)
    c = calibrate_magnetometer(H, ref, sample_period_s=DECIMATE)
    assert set(np.flatnonzero(~c.used)) == set(bad)
    assert np.all(np.abs((c.estimate - _truth_vector(ERRORS)) / c.sigma) < 4.0)


def test_input_errors(arc) -> None:  # noqa: ANN001
    B, ref = arc["B"], arc["ref"]
    with pytest.raises(MagnetometerCalibrationError, match="expected"):
        calibrate_magnetometer(B[:, :2], ref, sample_period_s=1.0)
    with pytest.raises(MagnetometerCalibrationError, match="at least 36"):
        calibrate_magnetometer(B[:10], ref[:10], sample_period_s=1.0)
    with pytest.raises(MagnetometerCalibrationError, match="dipole"):
        calibrate_magnetometer(B, ref, sample_period_s=1.0, settings=CalibrationSettings(estimate_coupling=True))
    bad = B.copy()
    bad[3, 1] = np.nan
    with pytest.raises(MagnetometerCalibrationError, match="not finite"):
        calibrate_magnetometer(bad, ref, sample_period_s=1.0)
