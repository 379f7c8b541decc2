"""Multi-head star-tracker accuracy (issue 19): coverage and false alarms of the per-head sigmas from the
relative attitude of several heads (processing.star_tracker.multi_head), over many seeds, on heads simulated
with scipy's Rotation (independent of the project's rotation code; the same model as
tests/processing/star_tracker/test_multi_head.py): a body turning at a constant rate, 1 Hz heads, white or
first-order Gauss-Markov noise about each head's axes, optionally a 20" thermal oscillation of one mounting.

Run: ``.venv/bin/python bench/star_tracker_heads.py [--seeds N] [--samples N]``. Prints per case the std of
the z-scores (sigma - truth) / sigma_sigma per head and axis (1 for an honest uncertainty), the fraction within
3 sigma, how often correlated residuals / any warning were raised, and the time per estimate.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: the tests' simulator

from processing.star_tracker.multi_head import MultiHeadSettings, analyze_heads, multi_head_warnings  # noqa: E402
from tests.processing.star_tracker.test_multi_head import M1, M2, M3, SAME, THREE, heads  # noqa: E402


def case(name: str, make, truth, settings: MultiHeadSettings, seeds: int) -> None:  # noqa: ANN001
    z, corr, warned, t0 = [], 0, 0, time.perf_counter()
    for s in range(seeds):
        r = analyze_heads(make(s), settings)
        z.append(((r.sigma_rad - np.asarray(truth) * np.pi / 648000) / r.sigma_sigma_rad).ravel())
        corr += r.correlated
        warned += bool(multi_head_warnings(r))
    z = np.array(z)
    print(f"{name:34} z std {np.round(np.nanstd(z, axis=0), 2).tolist()}  within 3 sigma "
          f"{np.mean(np.abs(z) < 3):.3f}  correlated {corr}/{seeds}  any warning {warned}/{seeds}  "
          f"{(time.perf_counter() - t0) / seeds:.2f} s each")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--samples", type=int, default=1800)
    a = ap.parse_args()
    n, k = a.samples, a.seeds
    same = MultiHeadSettings(identical_heads=True)
    case("two identical heads", lambda s: heads(s, n=n), SAME, same, k)
    case("three different heads", lambda s: heads(s, THREE, (M1, M2, M3), n=n), THREE, MultiHeadSettings(), k)
    case("three heads, unsynchronised", lambda s: heads(s, THREE, (M1, M2, M3), phases=(0, 0.5, 0.25), n=n), THREE,
         MultiHeadSettings(max_interpolation_s=1.5), k)
    case("two identical, 20\" thermal", lambda s: heads(s, n=max(n, 5800), thermal_arcsec=20.0), SAME, same, k)
    case("two identical, Gauss-Markov 30 s", lambda s: heads(s, n=n, gm_tau_s=30.0), SAME, same, k)
    print(f"(M1..M3: the mountings of the test; truth {SAME[0]}\" for identical heads, {THREE}\" for three)")


if __name__ == "__main__":
    main()
