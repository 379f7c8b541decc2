"""The definitive attitude on the papers' scenarios (issue 19): at least as accurate as gyro_bias_fit + the
orbital reconstruction on 003 (the ratio is printed and bounded), and in agreement with the 000 calibration
(alignment_calibration's processing) within the combined sigmas."""

from __future__ import annotations

import numpy as np
import pytest

from processing.definitive.comparison import compare_alignment, compare_gyro_bias_fit
from processing.definitive.estimate import estimate_definitive_attitude
from processing.definitive.model import DefinitiveSettings
from processing.simulate.seed000 import simulate_seed000
from processing.simulate.seed003 import simulate_seed003
from processing.star_tracker.orbital_attitude import orbital_attitude
from processing.units import ARCSEC_PER_RAD
from tests.processing.definitive.helpers import attitude_error, inputs_of

START = 1_700_000_000 * 10**9


def _rms(e: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(e**2, axis=0))


@pytest.mark.parametrize("seed", [0, 1])
def test_003_smoother_at_least_as_accurate_as_bias_fit_and_orbital_reconstruction(seed, capsys):
    sc = simulate_seed003(start_tai_ns=START, seed=seed)
    tr = sc.truth
    steps, heads, q_BG = inputs_of(sc)
    r = estimate_definitive_attitude(steps, heads, q_BG, DefinitiveSettings())
    cmp = compare_gyro_bias_fit(r, steps, heads, q_BG)
    at = np.searchsorted(r.time_tai_ns, tr.st_time_tai_ns)
    e_smooth = attitude_error(r.q_IB[at], tr.q_IB_st)
    e_fit = attitude_error(cmp["q_IB_gyro_bias_fit"], tr.q_IB_st)
    st, g = sc.streams["star_tracker"], sc.streams["gnss"]
    orb = orbital_attitude(st["time_tai_ns"], np.stack([st[f"q{i}"] for i in range(4)], 1), g["time_tai_ns"],
                           np.stack([g["x"], g["y"], g["z"]], 1), np.stack([g["vx"], g["vy"], g["vz"]], 1),
                           q_BS=tr.q_BS)
    k = np.searchsorted(tr.st_time_tai_ns, orb.time_tai_ns)
    e_orb = attitude_error(orb.q_GB, tr.q_IB_st[k])
    total = {name: float(np.sqrt(np.sum(_rms(e) ** 2))) for name, e in
             (("smoother", e_smooth), ("gyro_bias_fit", e_fit), ("orbital_attitude", e_orb))}
    with capsys.disabled():
        print(f"\n003 seed {seed}: total rms attitude error [arcsec] " +
              ", ".join(f"{k} {v * ARCSEC_PER_RAD:.2f}" for k, v in total.items()) +
              f"; ratio smoother/gyro_bias_fit {total['smoother'] / total['gyro_bias_fit']:.2f}, "
              f"smoother/orbital_attitude {total['smoother'] / total['orbital_attitude']:.2f}")
    assert total["smoother"] <= total["gyro_bias_fit"]
    assert total["smoother"] <= total["orbital_attitude"]
    for row in cmp["rows"]:
        assert abs(row["difference_over_combined_sigma"]) < 3, row
    z = (r.bias_B_rad_s.mean(axis=0) - tr.gyro_bias0_rad_s) / r.bias_sigma_G_rad_s.mean(axis=0)
    assert np.all(np.abs(z) < 3)


def test_000_agrees_with_alignment_calibration_within_combined_sigmas(capsys):
    sc = simulate_seed000(start_tai_ns=START, seed=2)
    tr = sc.truth
    steps, heads, q_BG = inputs_of(sc)
    r = estimate_definitive_attitude(steps, heads, q_BG, DefinitiveSettings(estimate_scale_factors=True,
                                                                            estimate_misalignment=True))
    cmp = compare_alignment(r, steps, heads, q_BG)
    rows = cmp["rows"]
    with capsys.disabled():
        print("\n000 seed 2: " + "; ".join(f"{x['quantity']} {x['axis']}: ours {x['ours']:.3g} theirs "
                                           f"{x['theirs'] if x['theirs'] is None else format(x['theirs'], '.3g')} "
                                           f"z {x['difference_over_combined_sigma']}" for x in rows))
    assert {x["quantity"] for x in rows} >= {"misalignment rotation (gyro axes)", "scale factor error"}
    for x in rows:
        if x["difference_over_combined_sigma"] is not None and x["quantity"] != "gyro drift at the end (gyro axes)":
            assert abs(x["difference_over_combined_sigma"]) < 3, x
    delta = np.array([x["ours"] for x in rows if x["quantity"].startswith("misalignment")])
    sig = np.array([x["ours_sigma"] for x in rows if x["quantity"].startswith("misalignment")])
    assert np.all(np.abs(delta - tr.misalignment_rad) < 3 * sig + 1e-8)
    scale = np.array([x["ours"] for x in rows if x["quantity"] == "scale factor error"])
    s_sig = np.array([x["ours_sigma"] for x in rows if x["quantity"] == "scale factor error"])
    assert np.all(np.abs(scale - tr.scale_factor_error) < 3 * s_sig + 1e-9)
