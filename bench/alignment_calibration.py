"""Alignment-calibration benchmark (issue 7): one hour of 128 Hz gyro increments (460,800 samples) and
1 Hz star-tracker quaternions of the seed-000 scenario, calibrated end to end by the job's task
(``alignment_calibration``: two-pass filter, eq. 7 integration, drift observer, QUEST alignment,
iterations, summary and tables; figures timed separately).

Run: ``.venv/bin/python bench/alignment_calibration.py [--duration-s 3600] [--seed 0] [--repeat 3]``.
Target: under 20 s end to end. Also prints the errors against the simulator's truth.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from app.jobs.types.alignment_calibration import JOB
from processing.simulate.seed000 import simulate_seed000
from processing.spacecraft import Spacecraft
from processing.tasks import TaskInputs
from processing.units import NS_PER_S, RAD_PER_ARCSEC

TARGET_S = 20.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration-s", type=float, default=3600.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    start = 1_700_000_000 * NS_PER_S
    t = time.perf_counter()
    scenario = simulate_seed000(start_tai_ns=start, duration_s=args.duration_s, seed=args.seed)
    t_sim = time.perf_counter() - t
    n_gyro = scenario.streams["gyro_increments"]["time_tai_ns"].size
    n_st = scenario.streams["star_tracker"]["time_tai_ns"].size
    inputs = TaskInputs(streams=scenario.streams, spacecraft=Spacecraft.from_json(scenario.config), start_tai_ns=start,
                        end_tai_ns=start + int(args.duration_s * NS_PER_S))
    params = JOB.params()
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        result = JOB.run(inputs, params, lambda fraction, stage: None)
        times.append(time.perf_counter() - t)
    t = time.perf_counter()
    JOB.figures(result, params)
    t_fig = time.perf_counter() - t
    s, tr = result.summary, scenario.truth
    best = min(times)
    print(f"seed-000 scenario: {args.duration_s:.0f} s, {n_gyro:,} gyro increments (128 Hz), {n_st:,} star-tracker "
          f"samples (1 Hz); simulated in {t_sim:.2f} s")
    print(f"alignment_calibration end to end: best {best:.2f} s, median {np.median(times):.2f} s over {args.repeat} "
          f"runs ({n_gyro / best:,.0f} increments/s); figures {t_fig:.2f} s")
    print(f"target < {TARGET_S:.0f} s: {'met' if best < TARGET_S else 'NOT met'}")
    mis_err = (np.array(s["misalignment_rad"], dtype=float) - tr.misalignment_rad) / RAD_PER_ARCSEC
    drift_err = (np.array(s["drift_rad_s"]) - tr.drift_G_rad_s(args.duration_s)) / RAD_PER_ARCSEC
    print(f"passes {s['iterations']} (converged {s['converged']}), windows {s['calibration_windows']}, "
          f"drift convergence {s['drift_convergence_s']} s")
    print(f"misalignment error [arcsec] {np.round(mis_err, 3)} (sigma {np.round(s['misalignment_sigma_arcsec'], 3)})")
    print(f"scale-factor error {100 * (s['scale_factor_error'] - tr.scale_factor_error):+.5f} % "
          f"(sigma {100 * s['scale_factor_error_sigma']:.5f} %)")
    print(f"drift error at the end [arcsec/s] {np.round(drift_err, 4)}")


if __name__ == "__main__":
    main()
