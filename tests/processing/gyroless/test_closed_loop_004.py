"""What the 004 closed loop achieves with the EKF of 004 on board (issue 18 item 4; the figures over
more orbits and both sensor models are in bench/gyroless_closed_loop.py and the README): 004's disturbance,
Sun fixed at S_orb = (0, 1, 0), realistic sensor noise, start at (0, 0, 0), steady state = the second orbit."""

import numpy as np
import pytest

from processing.gyroless.filtering import attitude_errors_rad
from processing.simulate.seed004 import orbit_period_s, simulate_seed004
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
T = orbit_period_s()


def _run(controller: str, **kw) -> dict:  # noqa: ANN003
    tr = simulate_seed004(start_tai_ns=T0, duration_s=2 * T, seed=4, controller=controller, estimator="ekf",  # type: ignore[arg-type]
                          sun_model="paper", initial_angles_deg=(0.0, 0.0, 0.0), **kw).truth
    steady = np.arange(tr.time_tai_ns.size) >= int(T)
    ang = np.degrees(np.column_stack([tr.roll_rad, tr.pitch_rad, tr.yaw_rad]))[steady]
    est = np.degrees(attitude_errors_rad(tr.q_OB_onboard, tr.q_OB))[steady]
    return {"rms": np.sqrt(np.mean(ang**2, axis=0)), "peak": np.abs(ang).max(axis=0),
            "est_rms": np.sqrt(np.mean(est**2, axis=0))}


@pytest.fixture(scope="module")
def loops() -> dict:
    return {"lqr": _run("lqr"), "energy": _run("energy"), "lqr_outage": _run("lqr", sun_outage_s=2000.0)}


def test_lqr_holds_yaw_under_1_deg_and_the_energy_law_does_not(loops: dict) -> None:
    assert loops["lqr"]["rms"][2] < 1.0  # 004: "less than one degree" in yaw with the averaged LQR
    assert loops["energy"]["rms"][2] > 3.0  # 004: "about four degrees" (here ~7)
    assert np.all(loops["lqr"]["est_rms"] < 0.2) and np.all(loops["energy"]["est_rms"] < 0.2)


def test_lqr_roll_and_pitch_are_not_within_2_deg_under_the_004_disturbance(loops: dict) -> None:
    """004 reports better than 2 deg with the LQR; under its own disturbance (-5e-6 N m about y at the
    orbital rate) the gravity-gradient pitch response is ~2.5 deg and the averaged LQR hardly opposes it."""
    rms, peak = loops["lqr"]["rms"], loops["lqr"]["peak"]
    assert np.all(rms < 4.0) and np.all(peak < 8.0)  # bounded ...
    assert max(peak[0], peak[1]) > 3.0 and rms[0] > 1.5  # ... but not "better than 2 deg"


def test_long_sun_outages_degrade_the_lqr(loops: dict) -> None:
    """004 figs. 5-6: 35 % outages degrade the LQR especially; here its yaw rms grows by half or more (the
    energy law's figures stay within a few per cent: bench/gyroless_closed_loop.py)."""
    assert loops["lqr_outage"]["rms"][2] > 1.3 * loops["lqr"]["rms"][2]
    assert np.all(loops["lqr_outage"]["est_rms"] > loops["lqr"]["est_rms"])  # the estimate degrades
    assert np.all(loops["lqr_outage"]["rms"][:2] < 1.2 * loops["lqr"]["rms"][:2])  # roll/pitch: the disturbance
