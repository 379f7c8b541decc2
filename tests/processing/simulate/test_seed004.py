"""Tests of the closed-loop 004 simulator (processing.simulate.seed004): streams and truth, and the
paper's qualitative results (issue 9, "Done when"):

- under the disturbance tau_d = [3e-6, -5e-6, 9.8e-7] sin(w0 t) N m the averaged LQR holds yaw within
  1 deg (rms) where the energy law lets it wander by several degrees (004: < 1 deg against ~4 deg);
- with the EKF in the loop the averaged LQR stabilises the transient from (-30, 10, -20) deg to better
  than 2 deg (rms per axis, third orbit; 004's conclusion).
"""

import math

import numpy as np
import pytest

from processing.attitude import rotations
from processing.environment import igrf_field_E_nT
from processing.gyroless.filtering import attitude_errors_rad
from processing.simulate.seed004 import Seed004ParameterError, orbit_period_s, simulate_seed004
from processing.streams import STREAMS
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
T_ORBIT = orbit_period_s()


def _orbit_slices(n: int) -> list[slice]:
    k = int(round(T_ORBIT))
    return [slice(i * k, (i + 1) * k) for i in range(n)]


def test_streams_config_and_truth_consistency() -> None:
    kw = {"start_tai_ns": T0, "duration_s": 300.0, "seed": 5, "controller": "energy", "estimator": "mekf",
          "sun_outage_s": 2000.0, "sun_outage_center_u_deg": 5.0, "q_BM": (0.5, 0.5, 0.5, 0.5)}
    sc = simulate_seed004(**kw)
    again = simulate_seed004(**kw)
    for name, cols in sc.streams.items():
        assert set(cols) == {"time_tai_ns", "sensor", *STREAMS[name].column_names}
        for c, v in cols.items():
            np.testing.assert_array_equal(v, again.streams[name][c])
    assert set(sc.config) == {"magnetometer", "sun_sensor", "inertia_kg_m2"}
    tr = sc.truth
    K = tr.time_tai_ns.size
    assert K == 301 and np.all(np.diff(tr.time_tai_ns) == 1_000_000_000)
    # the outage (2000 s centred at u = 5 deg, i.e. the first ~1000 s) removes the sun samples
    assert sc.streams["sun_sensor"]["time_tai_ns"].size == 0 and not tr.sun_visible.any()
    # magnetometer = dcm_MB dcm_BO B_O + noise (100 nT)
    q_BM = np.array(sc.config["magnetometer"]["q_BM"])
    B_M = rotations.quat_rotate(rotations.quat_conjugate(rotations.quat_multiply(tr.q_OB, q_BM)), tr.B_O_nT)
    res = np.column_stack([sc.streams["magnetometer"][c] for c in ("bx", "by", "bz")]) - B_M
    assert 80 < res.std() < 120 and abs(res.mean()) < 15
    # the truth field is IGRF-14 at the true position
    np.testing.assert_allclose(np.linalg.norm(tr.B_O_nT, axis=1),
                               np.linalg.norm(igrf_field_E_nT(tr.r_E, tr.time_tai_ns), axis=1), rtol=1e-12)
    # GNSS noise 5 m; kinematics: q_IB = q_IO o q_OB, w_BO consistent with the angles' start
    r = np.column_stack([sc.streams["gnss"][c] for c in ("x", "y", "z")]) - tr.r_E
    assert 3 < r.std() < 7
    np.testing.assert_allclose(np.degrees([tr.roll_rad[0], tr.pitch_rad[0], tr.yaw_rad[0]]), [-30, 10, -20], atol=1e-9)
    np.testing.assert_allclose(tr.omega_BO_B[0], 0.0, atol=1e-15)
    # dawn-dusk geometry: the Sun is close to +Y0 (004: S_orb = (0, 1, 0))
    assert np.all(tr.s_O[:, 1] > 0.95)


def test_parameter_errors() -> None:
    with pytest.raises(Seed004ParameterError, match="controller must be"):
        simulate_seed004(start_tai_ns=T0, duration_s=10.0, controller="pid")  # type: ignore[arg-type]
    with pytest.raises(Seed004ParameterError, match="sun_outage_s"):
        simulate_seed004(start_tai_ns=T0, duration_s=10.0, sun_outage_s=1e5)


@pytest.fixture(scope="module")
def disturbed() -> dict:
    """Steady state under 004's disturbance, both controllers with the true state fed back, 3 orbits."""
    return {c: simulate_seed004(start_tai_ns=T0, duration_s=3 * T_ORBIT, controller=c, estimator="truth",
                                initial_angles_deg=(0.0, 0.0, 0.0), magnetometer_noise_nT=0.0).truth
            for c in ("lqr", "energy")}


def test_lqr_holds_yaw_where_the_energy_law_does_not(disturbed: dict) -> None:
    tail = slice(int(round(T_ORBIT)), None)  # orbits 2-3
    yaw = {c: np.degrees(tr.yaw_rad[tail]) for c, tr in disturbed.items()}
    rms = {c: float(np.sqrt(np.mean(y**2))) for c, y in yaw.items()}
    peak = {c: float(np.abs(y).max()) for c, y in yaw.items()}
    assert rms["lqr"] < 1.0  # 004: "less than one degree" with the averaged LQR
    assert rms["energy"] > 3.0  # 004: "about four degrees" with the energy law
    assert peak["energy"] > 3 * peak["lqr"]
    # the disturbance acts and the loops stay bounded
    for tr in disturbed.values():
        assert np.abs(tr.tau_d_B_N_m).max(axis=0) == pytest.approx([3e-6, 5e-6, 9.8e-7], rel=1e-3)
        assert np.degrees(np.abs(tr.roll_rad[tail])).max() < 10 and np.degrees(np.abs(tr.pitch_rad[tail])).max() < 10


def test_ekf_in_the_loop_stabilises_better_than_2_deg() -> None:
    tr = simulate_seed004(start_tai_ns=T0, duration_s=3 * T_ORBIT, controller="lqr", estimator="ekf",
                          disturbance_N_m=(0.0, 0.0, 0.0)).truth
    first, _, third = _orbit_slices(3)
    ang = np.degrees(np.column_stack([tr.roll_rad, tr.pitch_rad, tr.yaw_rad]))
    np.testing.assert_allclose(ang[0], [-30, 10, -20], atol=1e-9)
    assert np.all(np.sqrt(np.mean(ang[third] ** 2, axis=0)) < 2.0)
    # the on-board EKF converged from its two-vector start and stays well below the control error
    est = np.degrees(attitude_errors_rad(tr.q_OB_onboard, tr.q_OB))
    assert np.all(np.sqrt(np.mean(est[third] ** 2, axis=0)) < 0.2)
    assert math.isfinite(float(np.abs(tr.mu_B_A_m2).max()))
