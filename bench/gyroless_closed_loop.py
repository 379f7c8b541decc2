"""The closed loop of paper 004 (issue 18 item 4): the EKF of 004 on board feeding the energy law (eq. 6)
or the averaged LQR (eq. 7), as in 004's figures 3-7, measured on processing.simulate.seed004.

Scenarios (650 km, 98 deg, J = diag(51.44, 51.48, 0.76) kg m^2, T_s = 1 s, Sun fixed at S_orb = (0, 1, 0)
as in 004, w_BO = 0 at the start, ``--orbits`` orbits, default 3):

- fig3: the transient from (-30, 10, -20) deg without disturbance: time after which every angle stays within
  5 deg and 2 deg, rms and peak over orbits 2..N;
- fig4: steady state (start at (0, 0, 0), orbits 2..N: rms and peak |roll|, |pitch|, |yaw|) under 004's
  disturbance tau_d = (3e-6, -5e-6, 9.8e-7) sin(w0 t) N m;
- fig5 / fig6: the same with sun-sensor outages of 2000 s (35 %) and 1000 s (17 %) per orbit;
- fig7: the same with 004's 2 % field-model error (B_meas = B + 0.02 (1, -1, 1) |B|).

Each for both controllers, with noise-free sensors as in 004 ("paper") and with the simulator's realistic
noise (magnetometer 100 nT, sun sensor 0.5 deg; ``--noise realistic`` or ``both``). Also the on-board
EKF's own error (rms over the steady part). Run:
``.venv/bin/python bench/gyroless_closed_loop.py [--orbits N] [--noise paper|realistic|both]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from processing.gyroless.filtering import attitude_errors_rad
from processing.simulate.seed004 import orbit_period_s, simulate_seed004
from processing.time.timescales import iso_to_tai_ns

ZERO = {"initial_angles_deg": (0.0, 0.0, 0.0)}
SCENARIOS = {
    "fig3": {"disturbance_N_m": (0.0, 0.0, 0.0)},
    "fig4": ZERO,
    "fig5": {**ZERO, "sun_outage_s": 2000.0},
    "fig6": {**ZERO, "sun_outage_s": 1000.0},
    "fig7": {**ZERO, "field_model_error": 0.02},
}
NOISE = {"paper": {"magnetometer_noise_nT": 0.0, "sun_sensor_noise_deg": 0.0},
         "realistic": {"magnetometer_noise_nT": 100.0, "sun_sensor_noise_deg": 0.5}}


def _settling_s(t: np.ndarray, ang: np.ndarray, limit_deg: float) -> float | None:
    """First time after which every |angle| stays below limit_deg (None if never)."""
    bad = np.flatnonzero(np.any(np.abs(ang) >= limit_deg, axis=1))
    if bad.size == 0:
        return 0.0
    return None if bad[-1] == t.size - 1 else float(t[bad[-1] + 1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--orbits", type=int, default=3)
    ap.add_argument("--noise", choices=("paper", "realistic", "both"), default="both")
    args = ap.parse_args()
    t0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])
    T = orbit_period_s()
    print(f"004 closed loop with the on-board EKF, {args.orbits} orbits of {T:.0f} s; angles roll/pitch/yaw [deg]")
    for noise in (("paper", "realistic") if args.noise == "both" else (args.noise,)):
        print(f"\n== sensors: {noise} ({NOISE[noise]})")
        for name, kw in SCENARIOS.items():
            for ctrl in ("lqr", "energy"):
                c0 = time.process_time()
                sc = simulate_seed004(start_tai_ns=t0, duration_s=args.orbits * T, seed=4, controller=ctrl,
                                      estimator="ekf", sun_model="paper", **NOISE[noise], **kw)  # type: ignore[arg-type]
                cpu = time.process_time() - c0
                tr = sc.truth
                t = (tr.time_tai_ns - tr.time_tai_ns[0]) / 1e9
                ang = np.degrees(np.column_stack([tr.roll_rad, tr.pitch_rad, tr.yaw_rad]))
                steady = t >= T
                rms = np.sqrt(np.mean(ang[steady] ** 2, axis=0))
                peak = np.abs(ang[steady]).max(axis=0)
                est = np.degrees(attitude_errors_rad(tr.q_OB_onboard, tr.q_OB))[steady]
                est_rms = np.sqrt(np.mean(est**2, axis=0))
                line = f"  {name} {ctrl:6s}: steady rms {np.round(rms, 2).tolist()} peak {np.round(peak, 2).tolist()}"
                if name == "fig3":
                    s2, s5 = _settling_s(t, ang, 2.0), _settling_s(t, ang, 5.0)
                    line += (f"; settles within 5 deg after {s5 if s5 is None else round(s5)} s, within 2 deg after "
                             f"{s2 if s2 is None else round(s2)} s")
                if "sun_outage_s" in kw:
                    out = steady & ~tr.sun_visible
                    lit = steady & tr.sun_visible
                    e_out = np.sqrt(np.mean(np.sum(ang[out] ** 2, axis=1))) if out.any() else np.nan
                    e_lit = np.sqrt(np.mean(np.sum(ang[lit] ** 2, axis=1))) if lit.any() else np.nan
                    line += f"; total-angle rms in outage {e_out:.2f}, sunlit {e_lit:.2f}"
                line += f"; on-board EKF error rms {np.round(est_rms, 3).tolist()} ({cpu:.1f} s CPU)"
                print(line, flush=True)


if __name__ == "__main__":
    main()
