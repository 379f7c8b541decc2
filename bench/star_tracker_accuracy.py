"""Star-tracker accuracy benchmark (issue 4): 24 h of 1 Hz star-tracker quaternions (86,400 samples)
analysed end to end with the automatic harmonic count, against the dense least-squares route in the
same run.

Run: ``.venv/bin/python bench/star_tracker_accuracy.py [--hours H] [--rate-hz R] [--repeat K] [--spectra-only]
[--gap-fraction F]``. Target: under 3 s for the default 24 h at 1 Hz without gaps (DST route); with
``--gap-fraction 0.03`` the segments with gaps take the general least-squares route (both columns then
show it). Then, in the same run, the irregular case of real telemetry (issue 23): the same day with time
tags jittered by up to ``--jitter-s`` (0.05 s) and 1 % of the samples removed in 10-s blocks, which takes
the general route in every segment (Gram matrix by NUFFT + Cholesky) and the NUFFT spectra; target < 5 s.

Data (generated here, not timed): the seed-003 attitude model (processing.simulate: 830 km circular
sun-synchronous orbit, orbital orientation, pitch/yaw/roll as sums of slow sinusoids with periods of
184..1080 s and +-0.3 deg, plus the 0.4 Hz, 3" mirror vibration) extended to 24 h, the 003 mounting,
and white noise of 2.5/5/15 arcsec about the sensor axes, without gaps. The analysis splits the day
into 72 segments of 20 min (003 §1.3), chooses M per segment (2 x GCV, processing.star_tracker.accuracy)
and computes residuals, sigmas, rates, the residual spectrum and its lines.

Baseline: the same call with ``method="lstsq"``, i.e. every harmonics path and fit by Householder QR
of the dense design [1, tau, sin(pi m tau)] instead of the DST route. Both must give the same sigmas.

OpenBLAS: on a small shared machine its thread pool can make a single small QR take 0.3 s; this
script pins it to one thread unless OPENBLAS_NUM_THREADS is already set (say so in reports).
"""

from __future__ import annotations

import os

from processing.units import R_EARTH_M, RAD_PER_ARCSEC, RAD_PER_DEG

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy.fft  # noqa: E402

from processing.attitude import rotations  # noqa: E402
from processing.orbits.two_body import sun_synchronous_inclination_rad
from processing.signal.spectral import amplitude_spectrum_of_samples  # noqa: E402
from processing.simulate.orbital_attitude_model import OrbitalAttitudeModel, SinusoidSeries  # noqa: E402
from processing.simulate.seed003 import ST_NOISE_STD_003_RAD, mounting_q_BS_003
from processing.star_tracker.accuracy import analyze_star_tracker_accuracy  # noqa: E402

START_TAI_NS = 1_259_661_600 * 1_000_000_000  # 2009-12-01 (the 003 era); any epoch works


def day_of_quaternions(
    hours: float, rate_hz: float, gap_fraction: float = 0.0, seed: int = 0, jitter_s: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time_tai_ns (N,), q_IS (N, 4), q_BS (4,)): the seed-003 attitude model plus sensor noise,
    with gap_fraction of the samples removed in 10-s blocks at random places, sampled at times jittered
    uniformly by up to jitter_s."""
    rng = np.random.default_rng(seed)

    def series(mean_deg: float, amp_deg: float) -> SinusoidSeries:
        periods = np.array([900.0, 420.0, 230.0]) * rng.uniform(0.8, 1.2, 3)
        return SinusoidSeries(
            mean_rad=mean_deg * RAD_PER_DEG,
            amplitudes_rad=(*(amp_deg * RAD_PER_DEG * np.array([0.5, 0.3, 0.2])).tolist(), 3.0 * RAD_PER_ARCSEC),
            periods_s=(*periods.tolist(), 2.5),
            phases_rad=tuple(rng.uniform(0, 2 * np.pi, 4).tolist()),
        )

    a_m = R_EARTH_M + 830e3
    model = OrbitalAttitudeModel(
        a_m=a_m, inc_rad=float(sun_synchronous_inclination_rad(a_m)), raan_rad=100 * RAD_PER_DEG,
        u0_rad=20 * RAD_PER_DEG,
        pitch=series(0.0, 0.3), yaw=series(1.2, 0.25), roll=series(0.0, 0.3),
    )
    n = int(round(hours * 3600 * rate_hz))
    t_s = np.arange(n) / rate_hz + (rng.uniform(-jitter_s, jitter_s, n) if jitter_s > 0 else 0.0)
    t_ns = START_TAI_NS + np.round(t_s * 1e9).astype(np.int64)
    q_BS = mounting_q_BS_003()
    q_IS = rotations.quat_multiply(model.evaluate((t_ns - START_TAI_NS) / 1e9).q_IB, q_BS)
    noise = rng.standard_normal((n, 3)) * np.asarray(ST_NOISE_STD_003_RAD)
    q_IS = rotations.quat_canonical(rotations.quat_multiply(q_IS, rotations.rotvec_to_quat(noise)))
    block = max(1, int(round(10 * rate_hz)))
    starts = rng.choice(n // block, size=int(gap_fraction * n / block), replace=False) * block
    keep = np.ones(n, dtype=bool)
    keep[(starts[:, None] + np.arange(block)).ravel()] = False
    return t_ns[keep], q_IS[keep], q_BS


def timed(fn, repeat: int) -> tuple[float, float, object]:
    """Best wall-clock and CPU (process) time [s] of ``repeat`` calls, and the last result."""
    best, best_cpu, out = np.inf, np.inf, None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu, out


def spectrum_against_rfft(hours: float, repeat: int) -> None:
    """Issue 24: CPU of our 003 §1.5 spectra of a gyro-like day (10 Hz, both ends: N = 36,000 h + 1 rows x 3)
    against a plain ``scipy.fft.rfft`` of the same data at its own length N and at ``next_fast_len``."""
    n = int(round(hours * 36_000)) + 1
    t = 0.1 * np.arange(n)
    x = np.random.default_rng(2).standard_normal((n, 3)) + 1e-3 * np.sin(2 * np.pi * 0.4 * t)[:, None]
    keep = np.ones(n, dtype=bool)
    keep[n // 3:n // 3 + 600] = False  # one 60-s gap: the zero-filled (gapped) route
    _, plain, _ = timed(lambda: scipy.fft.rfft(x, axis=0), repeat)
    _, fast, _ = timed(lambda: scipy.fft.rfft(x, n=scipy.fft.next_fast_len(n, real=True), axis=0), repeat)
    print(f"spectra of {n} x 3 samples at 10 Hz: plain rfft (length {n}) {plain:.3f} s CPU, "
          f"at next_fast_len {fast:.3f} s CPU")
    for name, tt, xx in (("uniform", t, x), ("one gap", t[keep], x[keep])):
        _, ours, spec = timed(lambda tt=tt, xx=xx: amplitude_spectrum_of_samples(tt, xx), repeat)
        print(f"  {name:8s} ({spec.method}, {spec.freq_hz.size} frequencies): {ours:.3f} s CPU = "  # type: ignore[attr-defined]
              f"{ours / plain:.2f} x the plain rfft")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--rate-hz", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--gap-fraction", type=float, default=0.0,
                    help="remove this fraction of samples in 10-s blocks (general least-squares route)")
    ap.add_argument("--jitter-s", type=float, default=0.05, help="time-tag jitter of the irregular case [s]")
    ap.add_argument("--spectra-only", action="store_true",
                    help="only the spectrum timing of a gyro-like day against a plain scipy.fft.rfft")
    args = ap.parse_args()
    spectrum_against_rfft(args.hours, args.repeat)
    if args.spectra_only:
        return
    t_ns, q_IS, q_BS = day_of_quaternions(args.hours, args.rate_hz, args.gap_fraction)
    print(f"{t_ns.size} star-tracker samples over {args.hours} h at {args.rate_hz} Hz, gaps {args.gap_fraction:.0%} "
          f"(OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')})")
    fast_s, fast_cpu, fast = timed(lambda: analyze_star_tracker_accuracy(t_ns, q_IS, q_BS), args.repeat)
    dense_s, dense_cpu, dense = timed(
        lambda: analyze_star_tracker_accuracy(t_ns, q_IS, q_BS, method="lstsq"), max(1, args.repeat // 2))
    sig = fast.sigma_rad / RAD_PER_ARCSEC  # type: ignore[attr-defined]
    sig_dense = dense.sigma_rad / RAD_PER_ARCSEC  # type: ignore[attr-defined]
    methods = sorted({s.method for s in fast.segments})  # type: ignore[attr-defined]
    harmonics = fast.harmonics  # type: ignore[attr-defined]
    print(f"segments: {len(harmonics)}, harmonics per segment: min {min(harmonics)} median "
          f"{int(np.median(harmonics))} max {max(harmonics)}, route {methods}")
    print(f"sigma_arcsec (x1 x2 x3): {np.round(sig, 3).tolist()} (simulated 2.5, 5, 15; 0.4 Hz vibration in, "
          f"no gyro); sigma_smoothing_arcsec {np.round(fast.sigma_smoothing_rad / RAD_PER_ARCSEC, 3).tolist()}")  # type: ignore[attr-defined]
    print(f"dense-lstsq route agrees: max |d sigma| = {np.max(np.abs(sig - sig_dense)):.2e} arcsec")
    print(f"end to end ({'/'.join(methods)} route, best of {args.repeat}): {fast_s:.3f} s wall, {fast_cpu:.3f} s CPU"
          f"  [target < 3 s: {'OK' if fast_s < 3.0 else 'MISSED'}]")
    print(f"dense-lstsq baseline: {dense_s:.3f} s wall, {dense_cpu:.3f} s CPU  -> speed-up x{dense_s / fast_s:.1f} "
          f"(CPU x{dense_cpu / fast_cpu:.1f})")
    t_i, q_i, _ = day_of_quaternions(args.hours, args.rate_hz, 0.01, seed=1, jitter_s=args.jitter_s)
    irr_s, irr_cpu, irr = timed(lambda: analyze_star_tracker_accuracy(t_i, q_i, q_BS), args.repeat)
    routes = sorted({s.method for s in irr.segments})  # type: ignore[attr-defined]
    verdict = "OK" if irr_s < 5.0 else "MISSED"
    print(f"irregular case: {t_i.size} samples, jitter +-{args.jitter_s} s, 1 % gaps, route {routes}: "
          f"{irr_s:.3f} s wall, {irr_cpu:.3f} s CPU [target < 5 s: {verdict}] (regular case above: {fast_s:.3f} s); "
          f"sigma_arcsec {np.round(irr.sigma_rad / RAD_PER_ARCSEC, 3).tolist()}")  # type: ignore[attr-defined]
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
