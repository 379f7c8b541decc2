"""Ground post-processing of a gyroless microsatellite (paper 004): attitude and rate from magnetometer,
sun sensor and GNSS telemetry with the EKF of 004 or the MEKF, then the RTS smoother.

Pipeline (pure, arrays in, dataclass out):

1. Filter steps at the magnetometer samples. The orbit at each step is the GNSS ITRF state interpolated
   by cubic Hermite polynomials (positions and velocities; steps outside the GNSS span are dropped),
   taken to the GCRS (IAU 2006/2000A, zero EOP unless given; processing.frames.earth_rotation_interp).
2. Orbital frame of 004 from the inertial state (processing.frames.orbital.dcm_IO_lvlh_004), its rate
   w0 = |r x v| / r^2 and n^2 = mu / r^3 per step.
3. Reference directions in O: IGRF-14 field at the GNSS position (processing.environment.igrf) and the
   Sun seen from the spacecraft (processing.environment.sun). Sun-sensor samples are matched to the
   steps (nearest within half a step); samples in the Earth's shadow or penumbra (conical model) are
   not used and counted.
4. Measurements in B through the configured mountings q_BM, q_BS; direction noise per step
   sigma_b = sqrt(sigma_mag^2 + sigma_model^2) / |B_measured|, sigma_s = the sun sensor's.
5. Known torque per step: magnetorquer dipole (zero-order hold of the last command) x measured field.
6. Initialisation at the first step with both vectors: two-vector (TRIAD) solution, or given angles;
   w_BO = 0. Steps before it are dropped.
7. Filter (004's EKF or the MEKF; optionally with the magnetometer bias and a Gauss-Markov field error as
   states, processing.gyroless.ekf.ModelErrorStates), optional RTS smoother (processing.gyroless.rts_smoother);
   consistency statistics (processing.estimation.consistency) and gates
   (processing.gyroless.consistency_gates.filter_consistency, with the convergence time).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.attitude.rigid_body import q_OB_from_roll_pitch_yaw_004, roll_pitch_yaw_004
from processing.environment.eclipse import sunlit_fraction
from processing.environment.igrf import igrf_field_E_nT
from processing.environment.sun import sun_position_I_m
from processing.estimation.consistency import (
    ChiSquareStats,
    WhitenessStats,
    chi_square_stats,
    whiteness,
)
from processing.frames.earth_orientation import EarthOrientation
from processing.frames.earth_rotation_interp import itrs_to_gcrs_state_interp
from processing.frames.orbital import dcm_IO_lvlh_004
from processing.gyroless.consistency_gates import FilterConsistency, convergence_time, filter_consistency
from processing.gyroless.ekf import FilterTuning, ModelErrorStates
from processing.gyroless.filtering import FilterRun, GyrolessInputs, model_error_series, run_filter, triad_q_OB
from processing.gyroless.rts_smoother import SmoothedRun, rts_smooth
from processing.units import MU_EARTH_M3_S2, NS_PER_S, RAD_PER_DEG

__all__ = [
    "GyrolessError",
    "GyrolessResult",
    "GyrolessSettings",
    "PreparedInputs",
    "TUNING_DEFAULT",
    "TUNING_WITH_MODEL_ERRORS",
    "estimate_gyroless_attitude",
    "hermite_state",
    "prepare_gyroless_inputs",
]



class GyrolessError(ValueError):
    """Inputs that do not allow the estimation (too few samples, no overlap, bad mounting, ...)."""


TUNING_DEFAULT = FilterTuning()
"""Process noise without model-error states (the magnetometer pins the attitude; NIS/NEES at their
expected values on the 004 scenario, tests/processing/gyroless)."""
TUNING_WITH_MODEL_ERRORS = FilterTuning(torque_noise_psd_N2_m2_s=(1e-5) ** 2)
"""Process noise with magnetometer-bias or field-error states: the field then determines the attitude less
(about the orbit normal, where a dawn-dusk Sun adds nothing), the rates and pitch lean on the dynamics, and
the default unmodelled torque (4e-6 N m sqrt(s)) makes the filter overconfident there (3-sigma coverage of
the filtered error 0.73-0.78 on clean 004 orbits); 1e-5 N m sqrt(s) gives >= 0.99 (bench/gyroless_ekf.py)."""


@dataclass(frozen=True)
class GyrolessSettings:
    """Settings of the estimation; noise as 1-sigma per axis.

    filter: "ekf" (004) or "mekf"; smoother: run the RTS smoother. magnetometer_noise_nT,
    field_model_error_nT (added in quadrature; IGRF vs the real field, ~50-200 nT in LEO),
    sun_sensor_noise_deg. initial_angles_deg: (roll, pitch, yaw) instead of the two-vector start.
    initial_attitude_sigma_deg, initial_rate_sigma_rad_s, initial_disturbance_sigma_N_m: initial 1-sigma.
    tuning: process noise; None: :data:`TUNING_DEFAULT`, or :data:`TUNING_WITH_MODEL_ERRORS` when model-error
    states are estimated (see there). converged_sigma_deg, nis_window_s: convergence criterion (see
    :func:`estimate_gyroless_attitude`). eop: Earth orientation used for ITRF -> GCRS.
    estimate_magnetometer_bias, magnetometer_bias_sigma_nT: carry the magnetometer bias (in B) as 3 states
    with this prior 1-sigma; field_error_sigma_nT (> 0 turns it on), field_error_tau_s: the reference
    field's error in O as a first-order Gauss-Markov process (processing.gyroless.ekf.ModelErrorStates).
    """

    filter: Literal["ekf", "mekf"] = "mekf"
    smoother: bool = True
    magnetometer_noise_nT: float = 100.0
    field_model_error_nT: float = 0.0
    sun_sensor_noise_deg: float = 0.5
    initial_angles_deg: tuple[float, float, float] | None = None
    initial_attitude_sigma_deg: float = 10.0
    initial_rate_sigma_rad_s: float = 2e-3
    initial_disturbance_sigma_N_m: float = 1e-5
    tuning: FilterTuning | None = None
    converged_sigma_deg: float = 2.0
    nis_window_s: float = 600.0
    eop: EarthOrientation = field(default_factory=EarthOrientation)
    estimate_magnetometer_bias: bool = False
    magnetometer_bias_sigma_nT: float = 1000.0
    field_error_sigma_nT: float = 0.0
    field_error_tau_s: float = 1800.0

    def resolved_tuning(self) -> FilterTuning:
        """The process noise used: ``tuning``, else the default for the model-error states chosen."""
        if self.tuning is not None:
            return self.tuning
        return TUNING_WITH_MODEL_ERRORS if self.model_errors().n_states else TUNING_DEFAULT

    def model_errors(self) -> ModelErrorStates:
        return ModelErrorStates(magnetometer_bias=self.estimate_magnetometer_bias,
                                bias_sigma_nT=self.magnetometer_bias_sigma_nT,
                                field_error_sigma_nT=self.field_error_sigma_nT,
                                field_error_tau_s=self.field_error_tau_s)


@dataclass(frozen=True)
class GyrolessResult:
    """Estimated series on the filter steps (K) and consistency statistics.

    time_tai_ns (K,); q_OB (K, 4) canonical (smoothed when the smoother ran, else filtered);
    roll/pitch/yaw_rad (K,); attitude_sigma_rad (K, 3) about the B axes; omega_BI_B, omega_BO_B (K, 3)
    rad/s and rate_sigma_rad_s (K, 3); tau_d_O_N_m (K, 2); q_IB (K, 4) inertial (GCRS) attitude;
    filtered: the forward pass (:class:`FilterRun`); smoothed: :class:`SmoothedRun` or None.
    sun_used (K,) bool; sun_in_shadow (K,) bool (a sun sample fell in the shadow and was ignored);
    nis (K,), nis_dof (K,) of the forward pass; nis_stats, whiteness_stats; time_to_converge_s (from
    the first step) or None; consistency: the gates (:func:`filter_consistency`) over the steps after
    convergence; converged: a convergence time was found AND the gates pass; model_errors: the
    model-error states (smoothed when the smoother ran) {"magnetometer_bias_B_nT", "field_error_O_nT":
    (values (K, 3), 1-sigma (K, 3))} as far as estimated; counts: dict of sample counts; notes.
    """

    time_tai_ns: NDArray
    q_OB: NDArray
    roll_rad: NDArray
    pitch_rad: NDArray
    yaw_rad: NDArray
    attitude_sigma_rad: NDArray
    omega_BI_B: NDArray
    omega_BO_B: NDArray
    rate_sigma_rad_s: NDArray
    tau_d_O_N_m: NDArray
    q_IB: NDArray
    filtered: FilterRun
    smoothed: SmoothedRun | None
    sun_used: NDArray
    sun_in_shadow: NDArray
    nis: NDArray
    nis_dof: NDArray
    nis_stats: ChiSquareStats
    whiteness_stats: WhitenessStats
    time_to_converge_s: float | None
    converged: bool
    consistency: FilterConsistency
    model_errors: dict[str, tuple[NDArray, NDArray]]
    counts: dict[str, int]
    notes: list[str]
    settings: GyrolessSettings


@dataclass(frozen=True)
class PreparedInputs:
    """Filter inputs prepared from telemetry: time_tai_ns (K,) of the steps used, inputs
    (:class:`GyrolessInputs`), initial q0_OB (4,) and omega0_BI_B (3,), dcm_IO (K, 3, 3) of the orbital
    frame, w0_rad_s (K,), sun_in_shadow (K,), k0 (steps dropped before the start), notes."""

    time_tai_ns: NDArray
    inputs: GyrolessInputs
    q0_OB: NDArray
    omega0_BI_B: NDArray
    dcm_IO: NDArray
    w0_rad_s: NDArray
    sun_in_shadow: NDArray
    k0: int
    notes: list[str]


def hermite_state(t_ns: NDArray, r: NDArray, v: NDArray, t_out_ns: NDArray) -> tuple[NDArray, NDArray]:
    """Cubic Hermite interpolation of positions r (N, 3) [m] with velocities v (N, 3) [m/s] at sample
    times t_ns (N,) (increasing int64) to t_out_ns (M,) within [t_ns[0], t_ns[-1]]. Returns r, v (M, 3)."""
    i = np.clip(np.searchsorted(t_ns, t_out_ns, side="right") - 1, 0, t_ns.size - 2)
    h = (t_ns[i + 1] - t_ns[i]) / NS_PER_S
    s = ((t_out_ns - t_ns[i]) / NS_PER_S / h)[:, None]
    hh = h[:, None]
    p0, p1, m0, m1 = r[i], r[i + 1], v[i] * hh, v[i + 1] * hh
    s2, s3 = s * s, s * s * s
    pos = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1
    vel = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0 + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * m1) / hh
    return pos, vel


def _mounting(q: ArrayLike | None, name: str) -> NDArray:
    if q is None:
        return np.eye(3)
    a = np.asarray(q, dtype=float)
    if a.shape != (4,) or not np.all(np.isfinite(a)) or abs(np.linalg.norm(a) - 1.0) > 1e-3:
        raise GyrolessError(f"{name} must be 4 finite numbers of unit norm (scalar first), got {q!r}")
    return rotations.quat_to_dcm(a)



def prepare_gyroless_inputs(
    *,
    mag_time_tai_ns: ArrayLike,
    mag_M_nT: ArrayLike,
    sun_time_tai_ns: ArrayLike,
    sun_S: ArrayLike,
    gnss_time_tai_ns: ArrayLike,
    gnss_r_E_m: ArrayLike,
    gnss_v_E_m_s: ArrayLike,
    inertia_kg_m2: ArrayLike,
    torquer_time_tai_ns: ArrayLike | None = None,
    torquer_mu_B_A_m2: ArrayLike | None = None,
    q_BM: ArrayLike | None = None,
    q_BS: ArrayLike | None = None,
    settings: GyrolessSettings = GyrolessSettings(),
) -> PreparedInputs:
    """Steps 1-6 of the module docstring: the filter inputs and the initial state from telemetry.

    mag_M_nT (N, 3) in the magnetometer frame; sun_S (S, 3) unit vectors in the sun-sensor frame;
    gnss ITRF r (G, 3) m, v (G, 3) m/s; inertia (3, 3) or (3,) kg m^2 (principal body axes);
    torquer mu (T, 3) A m^2 in B (optional; without it the control torque is unmodelled);
    q_BM, q_BS mountings (default identity). Times int64 tai_ns, increasing.
    """
    s = settings
    steps = _filter_steps(mag_time_tai_ns, mag_M_nT, gnss_time_tai_ns, gnss_r_E_m, gnss_v_E_m_s)  # 1
    t = steps.time_tai_ns
    dcm_BM, dcm_BS = _mounting(q_BM, "magnetometer.q_BM"), _mounting(q_BS, "sun_sensor.q_BS")
    orbit = _orbit_and_references(steps, s.eop)  # 1-3
    meas = _body_measurements(steps, orbit, dcm_BM, dcm_BS, sun_time_tai_ns, sun_S, s)  # 4
    torque = _control_torque(t, meas.B_B_nT, torquer_time_tai_ns, torquer_mu_B_A_m2)  # 5
    notes = [*steps.notes, *meas.notes, *torque.notes]
    # 6. start at the first step with both vectors
    both = np.flatnonzero(np.all(np.isfinite(meas.s_B), axis=1))
    if both.size == 0:
        raise GyrolessError("no sun-sensor sample matches a magnetometer sample outside the shadow: cannot initialise")
    k0 = int(both[0])
    if k0 > 0:
        notes.append(f"filter starts at the first step with both vectors ({k0} earlier steps dropped)")
    sl = slice(k0, None)
    b_O_unit = orbit.B_O / np.linalg.norm(orbit.B_O, axis=1, keepdims=True)
    if s.initial_angles_deg is not None:
        q0 = q_OB_from_roll_pitch_yaw_004(*(np.asarray(s.initial_angles_deg, dtype=float) * RAD_PER_DEG))
    else:
        q0 = triad_q_OB(b_O_unit[k0], orbit.s_O[k0], meas.b_B[k0], meas.s_B[k0])
    c2 = rotations.quat_rotate(rotations.quat_conjugate(q0), np.array([0.0, 1.0, 0.0]))
    inputs = GyrolessInputs(
        t_s=(t[sl] - t[k0]) / NS_PER_S, b_O=b_O_unit[sl], b_B=meas.b_B[sl], sigma_b_rad=meas.sigma_b_rad[sl],
        s_O=orbit.s_O[sl], s_B=meas.s_B[sl], sigma_s_rad=meas.sigma_s_rad[sl], torque_B_N_m=torque.torque_B_N_m[sl],
        w0_rad_s=orbit.w0_rad_s[sl], n2_rad2_s2=orbit.n2_rad2_s2[sl],
        b_O_norm_nT=np.linalg.norm(orbit.B_O[sl], axis=1),
        dipole_B_A_m2=None if torque.dipole_B_A_m2 is None else torque.dipole_B_A_m2[sl],
    )
    return PreparedInputs(time_tai_ns=t[sl], inputs=inputs, q0_OB=q0, omega0_BI_B=-orbit.w0_rad_s[k0] * c2,
                          dcm_IO=orbit.dcm_IO[sl], w0_rad_s=orbit.w0_rad_s[sl], sun_in_shadow=meas.in_shadow[sl], k0=k0,
                          notes=notes)


@dataclass(frozen=True)
class _Steps:
    """Step 1: the filter steps (the valid magnetometer samples inside the GNSS span): times (K,),
    field b_M (K, 3) nT in the magnetometer frame; the GNSS samples; notes."""

    time_tai_ns: NDArray
    b_M_nT: NDArray
    gnss_time_tai_ns: NDArray
    gnss_r_E_m: NDArray
    gnss_v_E_m_s: NDArray
    notes: tuple[str, ...]


def _filter_steps(mag_time_tai_ns: ArrayLike, mag_M_nT: ArrayLike, gnss_time_tai_ns: ArrayLike,
                  gnss_r_E_m: ArrayLike, gnss_v_E_m_s: ArrayLike) -> _Steps:
    notes: list[str] = []
    t_mag = np.asarray(mag_time_tai_ns, dtype=np.int64)
    b_M = np.asarray(mag_M_nT, dtype=float)
    t_gnss = np.asarray(gnss_time_tai_ns, dtype=np.int64)
    r_g, v_g = np.asarray(gnss_r_E_m, dtype=float), np.asarray(gnss_v_E_m_s, dtype=float)
    if b_M.shape != (t_mag.size, 3) or r_g.shape != (t_gnss.size, 3) or v_g.shape != (t_gnss.size, 3):
        raise GyrolessError(f"expected (N, 3) magnetometer and GNSS arrays matching their times, got {b_M.shape}, "
                            f"{r_g.shape}, {v_g.shape}")
    if t_gnss.size < 2 or np.any(np.diff(t_gnss) <= 0) or np.any(np.diff(t_mag) <= 0):
        raise GyrolessError("need >= 2 GNSS samples and strictly increasing magnetometer and GNSS times")
    keep = (t_mag >= t_gnss[0]) & (t_mag <= t_gnss[-1]) & np.all(np.isfinite(b_M), axis=1)
    keep &= np.linalg.norm(b_M, axis=1) > 0
    if np.count_nonzero(~keep):
        notes.append(f"{int(np.count_nonzero(~keep))} magnetometer samples outside the GNSS span or invalid: dropped")
    t, b_M = t_mag[keep], b_M[keep]
    if t.size < 3:
        raise GyrolessError(f"need >= 3 magnetometer samples inside the GNSS span, got {t.size}")
    return _Steps(t, b_M, t_gnss, r_g, v_g, tuple(notes))


@dataclass(frozen=True)
class _Orbit:
    """Steps 1-3 per filter step: inertial position r_I (K, 3) m, dcm_IO (K, 3, 3) of the orbital frame,
    w0 (K,) rad/s, n^2 (K,) rad^2/s^2, IGRF field B_O (K, 3) nT and the Sun direction s_O (K, 3) in O,
    the visible fraction of the solar disc (K,)."""

    r_I: NDArray
    dcm_IO: NDArray
    w0_rad_s: NDArray
    n2_rad2_s2: NDArray
    B_O: NDArray
    s_O: NDArray
    sunlit: NDArray


def _orbit_and_references(steps: _Steps, eop: EarthOrientation) -> _Orbit:
    """Hermite-interpolated GNSS orbit in the GCRS, the orbital frame of 004, IGRF-14 field and the Sun."""
    t = steps.time_tai_ns
    r_E, v_E = hermite_state(steps.gnss_time_tai_ns, steps.gnss_r_E_m, steps.gnss_v_E_m_s, t)
    r_I, v_I, dcm_EI = itrs_to_gcrs_state_interp(r_E, v_E, t, eop)
    dcm_IO = dcm_IO_lvlh_004(r_I, v_I)
    rr = np.linalg.norm(r_I, axis=1)
    w0 = np.linalg.norm(np.cross(r_I, v_I), axis=1) / rr**2
    n2 = MU_EARTH_M3_S2 / rr**3
    B_E = igrf_field_E_nT(r_E, t)
    B_O = np.einsum("kji,klj,kl->ki", dcm_IO, dcm_EI, B_E)
    sun_pos = sun_position_I_m(t)
    s_I = sun_pos - r_I
    s_I /= np.linalg.norm(s_I, axis=1, keepdims=True)
    s_O = np.einsum("kji,kj->ki", dcm_IO, s_I)
    return _Orbit(r_I, dcm_IO, w0, n2, B_O, s_O, sunlit_fraction(r_I, sun_pos))


@dataclass(frozen=True)
class _Measurements:
    """Step 4: field B_B (K, 3) nT in B, its unit vector b_B, the matched Sun direction s_B (K, 3) (NaN
    where none), in_shadow (K,), direction noise sigma_b, sigma_s (K,) rad, notes."""

    B_B_nT: NDArray
    b_B: NDArray
    s_B: NDArray
    in_shadow: NDArray
    sigma_b_rad: NDArray
    sigma_s_rad: NDArray
    notes: tuple[str, ...]


def _body_measurements(
    steps: _Steps, orbit: _Orbit, dcm_BM: NDArray, dcm_BS: NDArray, sun_time_tai_ns: ArrayLike, sun_S: ArrayLike,
    s: GyrolessSettings,
) -> _Measurements:
    """Measurements in B; sun samples matched to the steps (nearest within half a step), shadow excluded."""
    t = steps.time_tai_ns
    notes: list[str] = []
    B_B = steps.b_M_nT @ dcm_BM.T  # nT
    B_norm = np.linalg.norm(B_B, axis=1)
    b_B = B_B / B_norm[:, None]
    s_B = np.full((t.size, 3), np.nan)
    t_sun = np.asarray(sun_time_tai_ns, dtype=np.int64)
    sun = np.asarray(sun_S, dtype=float).reshape(-1, 3)
    step_ns = float(np.median(np.diff(t)))
    in_shadow = np.zeros(t.size, bool)
    if t_sun.size:
        j = np.clip(np.searchsorted(t_sun, t), 1, t_sun.size - 1) if t_sun.size > 1 else np.zeros(t.size, int)
        if t_sun.size > 1:
            j = np.where(np.abs(t_sun[j - 1] - t) < np.abs(t_sun[j] - t), j - 1, j)
        near = np.abs(t_sun[j] - t) <= 0.5 * step_ns
        vec = sun[j] @ dcm_BS.T
        nrm = np.linalg.norm(vec, axis=1)
        near &= np.isfinite(nrm) & (nrm > 0)
        in_shadow = near & (orbit.sunlit < 1.0)
        use = near & ~in_shadow
        s_B[use] = vec[use] / nrm[use, None]
        if np.any(in_shadow):
            notes.append(f"{int(in_shadow.sum())} sun-sensor samples in the Earth's shadow/penumbra (conical model) "
                         "ignored")
    sigma_b = np.sqrt(s.magnetometer_noise_nT**2 + s.field_model_error_nT**2) / B_norm
    sigma_s = np.full(t.size, max(s.sun_sensor_noise_deg, 1e-3) * RAD_PER_DEG)
    return _Measurements(B_B, b_B, s_B, in_shadow, sigma_b, sigma_s, tuple(notes))


@dataclass(frozen=True)
class _Torque:
    """Step 5: the known control torque (K, 3) N m in B and a note when it is not modelled."""

    torque_B_N_m: NDArray
    notes: tuple[str, ...]
    dipole_B_A_m2: NDArray | None = None


def _control_torque(t: NDArray, B_B_nT: NDArray, torquer_time_tai_ns: ArrayLike | None,
                    torquer_mu_B_A_m2: ArrayLike | None) -> _Torque:
    """Magnetorquer dipole (zero-order hold of the last command) x measured field."""
    torque = np.zeros((t.size, 3))
    if torquer_time_tai_ns is None or torquer_mu_B_A_m2 is None or not np.size(torquer_time_tai_ns):
        return _Torque(torque, ("no magnetorquer telemetry: control torques are not modelled (raise the torque noise "
                                "if the spacecraft was actively controlled)",))
    t_tq = np.asarray(torquer_time_tai_ns, dtype=np.int64)
    mu = np.asarray(torquer_mu_B_A_m2, dtype=float).reshape(-1, 3)
    i = np.searchsorted(t_tq, t, side="right") - 1
    has = i >= 0
    dipole = np.zeros((t.size, 3))
    dipole[has] = mu[i[has]]
    torque[has] = np.cross(dipole[has], B_B_nT[has] * 1e-9)
    return _Torque(torque, (), dipole)


def estimate_gyroless_attitude(
    *,
    mag_time_tai_ns: ArrayLike,
    mag_M_nT: ArrayLike,
    sun_time_tai_ns: ArrayLike,
    sun_S: ArrayLike,
    gnss_time_tai_ns: ArrayLike,
    gnss_r_E_m: ArrayLike,
    gnss_v_E_m_s: ArrayLike,
    inertia_kg_m2: ArrayLike,
    torquer_time_tai_ns: ArrayLike | None = None,
    torquer_mu_B_A_m2: ArrayLike | None = None,
    q_BM: ArrayLike | None = None,
    q_BS: ArrayLike | None = None,
    settings: GyrolessSettings = GyrolessSettings(),
) -> GyrolessResult:
    """Estimate q_OB, w_BI^B and the in-plane disturbance torque from telemetry (see module docstring).

    mag_M_nT (N, 3) in the magnetometer frame; sun_S (S, 3) unit vectors in the sun-sensor frame;
    gnss ITRF r (G, 3) m, v (G, 3) m/s; inertia (3, 3) or (3,) kg m^2 (principal body axes);
    torquer mu (T, 3) A m^2 in B (optional; without it the control torque is unmodelled);
    q_BM, q_BS mountings (default identity). Times int64 tai_ns, increasing.
    Convergence: first time from which the mean NIS over ``nis_window_s`` is inside its 99 % interval
    and the largest 1-sigma attitude bound is below ``converged_sigma_deg``; ``converged`` also needs the
    consistency gates over the steps after it (:func:`filter_consistency`) to pass.
    """
    s = settings
    prep = prepare_gyroless_inputs(
        mag_time_tai_ns=mag_time_tai_ns, mag_M_nT=mag_M_nT, sun_time_tai_ns=sun_time_tai_ns, sun_S=sun_S,
        gnss_time_tai_ns=gnss_time_tai_ns, gnss_r_E_m=gnss_r_E_m, gnss_v_E_m_s=gnss_v_E_m_s,
        inertia_kg_m2=inertia_kg_m2, torquer_time_tai_ns=torquer_time_tai_ns, torquer_mu_B_A_m2=torquer_mu_B_A_m2,
        q_BM=q_BM, q_BS=q_BS, settings=settings)
    inputs, q0, J, k0, notes = prep.inputs, prep.q0_OB, np.asarray(inertia_kg_m2, dtype=float), prep.k0, prep.notes
    t, w0, dcm_IO, in_shadow = prep.time_tai_ns, prep.w0_rad_s, prep.dcm_IO, prep.sun_in_shadow
    try:
        run = run_filter(s.filter, inputs, J, q0, prep.omega0_BI_B,
                         attitude_sigma_rad=s.initial_attitude_sigma_deg * RAD_PER_DEG,
                         rate_sigma_rad_s=s.initial_rate_sigma_rad_s,
                         disturbance_sigma_N_m=s.initial_disturbance_sigma_N_m, tuning=s.resolved_tuning(),
                         model_errors=s.model_errors())
    except ValueError as exc:
        raise GyrolessError(str(exc)) from exc
    sm = rts_smooth(run) if s.smoother else None
    x = sm.x if sm is not None else run.x_filt
    att_sig = sm.attitude_sigma_rad if sm is not None else run.attitude_sigma_rad
    rate_sig = sm.rate_sigma_rad_s if sm is not None else run.rate_sigma_rad_s
    me = model_error_series(x, s.filter, sm.P if sm is not None else run.P_filt, s.model_errors())
    q_OB = rotations.quat_canonical(x[:, 3:7])
    w_BI = x[:, 0:3]
    c2_all = rotations.quat_rotate(rotations.quat_conjugate(q_OB), np.array([0.0, 1.0, 0.0]))
    w_BO = w_BI + w0[:, None] * c2_all
    roll, pitch, yaw = roll_pitch_yaw_004(q_OB)
    q_IB = rotations.quat_canonical(rotations.quat_multiply(rotations.dcm_to_quat(dcm_IO), q_OB))
    nis_st = chi_square_stats(run.nis, run.nis_dof)
    white = whiteness(run.whitened[:, :4] if s.filter == "mekf" else run.whitened, max_lag=20)
    t_conv = convergence_time(inputs.t_s, np.degrees(run.attitude_sigma_rad.max(axis=1)), run.nis, run.nis_dof,
                          s.converged_sigma_deg, s.nis_window_s)
    start = t_conv if t_conv is not None else min(s.nis_window_s, float(inputs.t_s[-1] - inputs.t_s[0]) / 2)
    gate = filter_consistency(inputs.t_s, run.nis, run.nis_dof, run.whitened[:, :4] if s.filter == "mekf"
                              else run.whitened, start, s.nis_window_s)
    counts = {
        "n_steps": int(t.size),
        "n_magnetometer_used": int(np.count_nonzero(run.used_mag)),
        "n_sun_used": int(np.count_nonzero(run.used_sun)),
        "n_sun_in_shadow": int(np.count_nonzero(in_shadow)),
        "n_dropped_before_start": k0,
    }
    return GyrolessResult(
        time_tai_ns=t, q_OB=q_OB, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, attitude_sigma_rad=att_sig,
        omega_BI_B=w_BI, omega_BO_B=w_BO, rate_sigma_rad_s=rate_sig, tau_d_O_N_m=x[:, 7:9], q_IB=q_IB,
        filtered=run, smoothed=sm, sun_used=run.used_sun, sun_in_shadow=in_shadow, nis=run.nis,
        nis_dof=run.nis_dof, nis_stats=nis_st, whiteness_stats=white, time_to_converge_s=t_conv,
        converged=t_conv is not None and gate.consistent, consistency=gate, model_errors=me,
        counts=counts, notes=notes, settings=s,
    )
