"""Robust star-tracker accuracy benchmark (issue 17 item 3): the many-seed figures behind
tests/processing/star_tracker/test_star_tracker_robust.py, and the 24 h timing with gyro.

Run: ``.venv/bin/python bench/star_tracker_robust.py [--seeds N] [--gyro-seeds K] [--hours H]``
(defaults 200, 40, 24; ``--hours 0`` skips the timing). Cases on the seed-003 simulator
(processing.simulate.seed003: 20-min arcs, 3 s samples, 3 % gaps, noise 2.5/5/15" about x1 x2 x3):

- clean: white noise, no vibration, no gyro: coverage of the truth by ``sigma_ci95_rad`` (per axis and
  all), false-alarm rates of ``correlated_residuals`` and ``outliers_removed``, sigma errors vs truth;
- gauss_markov: first-order Gauss-Markov noise with tau = 30 s (same stationary std): detection rate of
  ``correlated_residuals``, sigma / truth and sigma_lower_bound / truth;
- outliers: 1 % of the samples 300" off about a random axis: exact recovery of the outlier set, sigma
  errors vs truth (and the figures without the rejection);
- gyro_line: the default scenario (0.4 Hz real vibration) plus a 10"/s, 0.25 Hz line in the gyro only,
  with gyro data (K seeds): how often the line is kept out and flagged, the real one removed, sigma errors;
- timing: H hours of seed-003 data with gyro (10 Hz) through the analysis (main without these checks: 3.5 s CPU
  for 24 h), and H hours of 1 Hz quaternions clean and with 1 % outliers.

OpenBLAS is pinned to one thread unless OPENBLAS_NUM_THREADS is set (its pool makes small QRs slow on a
shared 2-core machine; see bench/star_tracker_accuracy.py).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from processing.simulate.seed003 import simulate_seed003  # noqa: E402
from processing.star_tracker.accuracy import analyze_star_tracker_accuracy  # noqa: E402
from processing.units import RAD_PER_ARCSEC  # noqa: E402
from tests.processing.star_tracker.test_star_tracker_robust import analyze  # noqa: E402  (the tests' call)

START = 1_259_661_600 * 1_000_000_000
TRUTH = np.array([2.5, 5.0, 15.0]) * RAD_PER_ARCSEC
CALM = (0.0, 0.0, 0.0)


def quiet(seed: int, **kwargs):
    return simulate_seed003(start_tai_ns=START, seed=seed, gnss_period_s=1200.0, vibration_amplitude_rad=CALM,
                            gyro_period_s=1.0, **kwargs)


def pct(x) -> str:
    return " / ".join(f"{100 * v:.1f}" for v in np.atleast_1d(x)) + " %"


def clean(n: int) -> None:
    cov, fa_w, fa_o, err = [], [], [], []
    for s in range(n):
        r = analyze(quiet(s), gyro=False)
        ci = r.sigma_ci95_rad
        cov.append((ci[:, 0] <= TRUTH) & (TRUTH <= ci[:, 1]))
        fa_w.append(r.whiteness.correlated)
        fa_o.append(r.n_outliers > 0)
        err.append(r.sigma_rad / TRUTH - 1)
    e = np.abs(np.array(err))
    print(f"clean ({n} seeds): 95 % interval coverage x1/x2/x3 {pct(np.mean(cov, axis=0))}, all {pct(np.mean(cov))}")
    print(f"  false alarms: correlated_residuals {pct(np.mean(fa_w))}, outliers_removed {pct(np.mean(fa_o))}")
    print(f"  |sigma/truth - 1|: mean {pct(e.mean(axis=0))}, max {pct(e.max(axis=0))}")


def gauss_markov(n: int) -> None:
    det, ratio, lower = [], [], []
    for s in range(n):
        r = analyze(quiet(s, st_noise_tau_s=30.0), gyro=False)
        det.append(r.whiteness.correlated)
        ratio.append(r.sigma_rad / TRUTH)
        lower.append(r.sigma_lower_bound_rad / TRUTH)
    print(f"gauss_markov tau 30 s ({n} seeds): correlated_residuals raised {pct(np.mean(det))}")
    print(f"  sigma/truth mean {np.mean(ratio, axis=0).round(3)}, lower bound/truth mean "
          f"{np.mean(lower, axis=0).round(3)} (max {np.max(lower, axis=0).round(3)})")


def outliers(n: int) -> None:
    exact, err, err_plain = [], [], []
    for s in range(n):
        sc = quiet(s, st_outlier_fraction=0.01)
        r = analyze(sc, gyro=False)
        exact.append(np.array_equal(r.outlier, sc.truth.st_outlier_mask))
        err.append(r.sigma_rad / TRUTH - 1)
        if s < 20:
            err_plain.append(analyze(sc, gyro=False, outlier_alpha=0.0).sigma_rad / TRUTH - 1)
    e = np.abs(np.array(err))
    print(f"outliers 1 % x 300\" ({n} seeds): outlier set recovered exactly {pct(np.mean(exact))}")
    print(f"  |sigma/truth - 1|: mean {pct(e.mean(axis=0))}, max {pct(e.max(axis=0))}; "
          f"without rejection (20 seeds) mean sigma/truth {(1 + np.mean(err_plain, axis=0)).round(2)}")


def gyro_line(n: int) -> None:
    kept, flagged, real, err = [], [], [], []
    for s in range(n):
        sc = simulate_seed003(start_tai_ns=START, seed=s, gnss_period_s=1200.0,
                              gyro_line_amplitude_rad_s=(10.0 * RAD_PER_ARCSEC,) * 3, gyro_line_hz=0.25)
        r = analyze(sc, gyro=True)
        by = {round(c.freq_hz, 2): c for c in r.line_coherence}
        fake, true = by.get(0.25), by.get(0.4)
        kept.append(fake is not None and not fake.removed)
        flagged.append(fake is not None and fake.gyro_only)
        real.append(true is not None and true.removed)
        err.append(r.sigma_rad / TRUTH - 1)
    e = np.abs(np.array(err))
    print(f"gyro-only line 10\"/s at 0.25 Hz ({n} seeds, with gyro): kept out {pct(np.mean(kept))}, flagged "
          f"{pct(np.mean(flagged))}, real 0.4 Hz line removed {pct(np.mean(real))}")
    print(f"  |sigma/truth - 1|: mean {pct(e.mean(axis=0))}, max {pct(e.max(axis=0))}")


def timing(hours: float) -> None:
    sc = simulate_seed003(start_tai_ns=START, seed=0, duration_s=hours * 3600.0, gnss_period_s=3600.0)
    n_st = sc.streams["star_tracker"]["time_tai_ns"].size
    n_g = sc.streams["gyro"]["time_tai_ns"].size
    t0, c0 = time.perf_counter(), time.process_time()
    r = analyze(sc, gyro=True)
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    print(f"timing: {hours:g} h seed-003 with gyro ({n_st} quaternions, {n_g} gyro samples, {len(r.segments)} "
          f"segments): {dt:.2f} s wall, {dc:.2f} s CPU (load average {os.getloadavg()[0]:.1f}); "
          f"sigma {(r.sigma_rad / RAD_PER_ARCSEC).round(2)}\", warnings-relevant: "
          f"outliers {r.n_outliers}, correlated {r.whiteness.correlated}")


def timing_outliers_1hz(hours: float) -> None:
    """H hours of 1 Hz quaternions (bench/star_tracker_accuracy.py's day) with 1 % of them 300" off:
    every segment goes through the rejection and the general least-squares route."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from star_tracker_accuracy import day_of_quaternions

    from processing.attitude import rotations

    t, q, q_BS = day_of_quaternions(hours, 1.0)
    rng = np.random.default_rng(1)
    idx = rng.choice(t.size, t.size // 100, replace=False)
    axis = rng.standard_normal((idx.size, 3))
    axis *= 300.0 * RAD_PER_ARCSEC / np.linalg.norm(axis, axis=1, keepdims=True)
    q_out = q.copy()
    q_out[idx] = rotations.quat_multiply(q[idx], rotations.rotvec_to_quat(axis))
    for name, qq in (("clean", q), ("1 % outliers", q_out)):
        t0, c0 = time.perf_counter(), time.process_time()
        r = analyze_star_tracker_accuracy(t, qq, q_BS)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        print(f"timing: {hours:g} h at 1 Hz, {name}: {dt:.2f} s wall, {dc:.2f} s CPU; {r.n_outliers} rejected "
              f"(of {idx.size if qq is q_out else 0}), routes {sorted({s.method for s in r.segments})}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--gyro-seeds", type=int, default=40)
    ap.add_argument("--hours", type=float, default=24.0)
    args = ap.parse_args()
    print(f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}")
    for fn, n in ((clean, args.seeds), (gauss_markov, args.seeds), (outliers, args.seeds),
                  (gyro_line, args.gyro_seeds)):
        t0 = time.perf_counter()
        fn(n)
        print(f"  ({time.perf_counter() - t0:.0f} s)")
    if args.hours > 0:
        timing(args.hours)
        timing_outliers_1hz(args.hours)


if __name__ == "__main__":
    main()
