"""Real-telemetry figures (issue 23) on the realistic simulator mode (processing.simulate.realistic).

1. False-alarm rate of every screening criterion on clean realistic data (quantised, jittered 1 Hz, 5 %
   dropouts, three gaps of up to 135 s, a 180 deg yaw manoeuvre; no late tags), over --seeds hours.
2. Late GNSS tags (3.4 s, 2 blocks of 60 s per hour): found / missed / wrongly flagged by ``time_tag``,
   the error of the estimated offset, and the rejections by the other GNSS criteria (of good neighbours).
3. orbital_attitude through a 200 s yaw turn (harmonics 15, as a fixed-harmonics smoother would use):
   rms 3-2-1 angle errors against the truth inside the turn, segmented at the detected manoeuvre vs not,
   beside the unsmoothed error; and with the late tags kept vs dropped.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/realistic_telemetry.py [--seeds 20]`` (about 1 min per
10 seeds on one core).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from processing.screening.criteria import ScreeningParams, screen
from processing.simulate.realistic import simulate_realistic
from processing.spacecraft import Spacecraft
from processing.star_tracker.orbital_attitude import euler_angles, orbital_attitude
from processing.time.timescales import iso_to_tai_ns
from processing.units import ARCSEC_PER_RAD

T0 = int(iso_to_tai_ns("2023-06-01T00:00:00"))
PARAMS = ScreeningParams(energy_model="two_body")  # the simulator's orbit is two-body


def false_alarms(seeds: int) -> None:
    counts: dict[tuple[str, str], list[int]] = {}
    for seed in range(seeds):
        sc = simulate_realistic(start_tai_ns=T0, duration_s=3600.0, seed=seed, manoeuvre_start_s=1200.0,
                                n_late_blocks=0)
        res = screen(sc.streams, Spacecraft.from_json(sc.config), PARAMS)
        for stream, per in res.summary().items():
            for crit, d in per.items():
                c = counts.setdefault((stream, crit), [0, 0])
                c[0] += d["n_rejected"]
                c[1] += d["n_total"]
    print(f"1. false alarms on clean realistic data, {seeds} h ({seeds} seeds); limit 0.1 % per criterion")
    print(f"   {'stream':14s} {'criterion':16s} {'rejected':>9s} {'samples':>9s} {'rate':>9s} {'95% upper':>10s}")
    for (stream, crit), (r, n) in sorted(counts.items()):
        upper = (r + 3.0) / n if r == 0 else (r + 2.0 * np.sqrt(r)) / n  # rule of three / ~2 sigma Poisson
        print(f"   {stream:14s} {crit:16s} {r:9d} {n:9d} {100 * r / n:8.4f}% {100 * upper:9.4f}%")


def late_tags(seeds: int) -> None:
    found = missed = wrong = others = n_late = 0
    offset_err = []
    for seed in range(seeds):
        sc = simulate_realistic(start_tai_ns=T0, duration_s=3600.0, seed=100 + seed, n_late_blocks=2,
                                late_block_s=60.0)
        res = screen(sc.streams, Spacecraft.from_json(sc.config), PARAMS)
        late = sc.truth.gnss_late
        tt = next(c for c in res.criteria if c.stream == "gnss" and c.name == "time_tag").flagged
        n_late += int(late.sum())
        found += int((tt & late).sum())
        missed += int((~tt & late).sum())
        wrong += int((tt & ~late).sum())
        others += int((res.rejected("gnss") & ~tt).sum())
        for f in res.findings.get("gnss_time_tags", []):
            offset_err.append(f["offset_s_median"] - sc.truth.late_tag_s)
    err = np.abs(np.asarray(offset_err)) if offset_err else np.array([np.nan])
    print(f"2. late GNSS tags (3.4 s), {seeds} seeds: {n_late} late states, found {found}, missed {missed}, "
          f"wrongly flagged {wrong}; other GNSS rejections {others}; |offset error| max {1e3 * err.max():.2f} ms")


def _angle_rms(res, sc, mask_turn: bool, raw: bool = False) -> np.ndarray:
    idx = np.searchsorted(sc.truth.st_time_tai_ns, res.time_tai_ns)
    truth = euler_angles(sc.truth.st_q_OB[idx], "321")
    got = (res.pitch_raw_rad, res.yaw_raw_rad, res.roll_raw_rad) if raw else (res.pitch_rad, res.yaw_rad, res.roll_rad)
    err = np.stack([np.angle(np.exp(1j * (a - b))) for a, b in zip(got, truth, strict=True)], axis=1) * ARCSEC_PER_RAD
    a, b = sc.truth.manoeuvre_tai_ns
    sel = (res.time_tai_ns >= a) & (res.time_tai_ns <= b)
    return np.sqrt(np.mean(err[sel if mask_turn else slice(None)] ** 2, axis=0))


def orbital(seed: int) -> None:
    for late in (0, 2):
        sc = simulate_realistic(start_tai_ns=T0, duration_s=3600.0, seed=200 + seed, manoeuvre_start_s=1200.0,
                                manoeuvre_duration_s=200.0, n_late_blocks=late, late_block_s=60.0)
        st, g = sc.streams["star_tracker"], sc.streams["gnss"]
        args = (st["time_tai_ns"], np.stack([st[f"q{i}"] for i in range(4)], axis=1), g["time_tai_ns"],
                np.stack([g[c] for c in ("x", "y", "z")], axis=1), np.stack([g[c] for c in ("vx", "vy", "vz")], axis=1))
        if late == 0:
            t = time.perf_counter()
            seg = orbital_attitude(*args, q_BS=sc.truth.q_BS, euler_sequence="321", harmonics=15)
            dt = time.perf_counter() - t
            flat = orbital_attitude(*args, q_BS=sc.truth.q_BS, euler_sequence="321", harmonics=15,
                                    segment_at_manoeuvres=False)
            (m0, m1), = seg.manoeuvres_tai_ns
            a, b = sc.truth.manoeuvre_tai_ns
            print(f"3. yaw turn of 200 s (detected {(m0 - a) / 1e9:+.1f} s / {(m1 - b) / 1e9:+.1f} s from the truth's "
                  f"start / end; {dt:.1f} s for 1 h): rms 3-2-1 (pitch, yaw, roll) error in the turn [arcsec]")
            print(f"   unsmoothed {np.round(_angle_rms(seg, sc, True, raw=True), 2)}, smoothed and segmented "
                  f"{np.round(_angle_rms(seg, sc, True), 2)}, smoothed across the turn "
                  f"{np.round(_angle_rms(flat, sc, True), 2)}")
        else:
            kept = orbital_attitude(*args, q_BS=sc.truth.q_BS, euler_sequence="321", smoothing=False,
                                    drop_late_gnss_tags=False)
            dropped = orbital_attitude(*args, q_BS=sc.truth.q_BS, euler_sequence="321", smoothing=False)
            c = kept.gnss_check
            print(f"   late tags: GNSS fit residuals {max(c.rms_ratio):.0f} x the noise, cause: {c.cause}")
            print(f"   unsmoothed angle rms over the hour [arcsec]: late tags kept "
                  f"{np.round(_angle_rms(kept, sc, False, raw=True), 2)} (reported orbit-frame sigma "
                  f"{np.round(kept.orbit_frame_sigma_rad * ARCSEC_PER_RAD, 1)}), dropped "
                  f"{np.round(_angle_rms(dropped, sc, False, raw=True), 2)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args()
    false_alarms(args.seeds)
    late_tags(args.seeds)
    orbital(0)


if __name__ == "__main__":
    main()
