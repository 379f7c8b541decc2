"""Per-head accuracy from the relative attitude of several star-tracker heads (processing.star_tracker.multi_head).

The heads are simulated here with scipy's Rotation (independent of the project's rotation code): a body
turning at a constant rate, heads mounted with q_BS, noise about each head's axes (white, or first-order
Gauss-Markov), optionally a thermal oscillation of one head's mounting or unsynchronised sampling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from processing.star_tracker.multi_head import (
    HeadSeries,
    MultiHeadError,
    MultiHeadSettings,
    analyze_heads,
    multi_head_warnings,
)

AS = np.pi / 180 / 3600
T0 = 1_700_000_000 * 10**9
M1 = Rotation.from_euler("x", -150, degrees=True)
M2 = Rotation.from_euler("z", 100, degrees=True) * M1
M3 = Rotation.from_euler("y", 70, degrees=True) * M1
SAME = ((3, 4, 18), (3, 4, 18))
THREE = ((2, 4, 18), (5, 3, 25), (3, 3, 10))


def heads(seed: int, sigmas=SAME, mounts=(M1, M2), phases=None, n=1800, gm_tau_s=None,  # noqa: ANN001
          thermal_arcsec=0.0) -> list[HeadSeries]:
    rng = np.random.default_rng(seed)
    out = []
    for h, (sig, m) in enumerate(zip(sigmas, mounts, strict=True)):
        t = (phases[h] if phases else 0.0) + np.arange(n, dtype=float)
        body = Rotation.from_rotvec(np.outer(t, [1e-3, 2e-4, -5e-4])) * Rotation.from_euler("xyz", [10, 20, 30],
                                                                                             degrees=True)
        noise = rng.standard_normal((n, 3)) * np.array(sig) * AS
        if gm_tau_s:
            a = np.exp(-1.0 / gm_tau_s)
            for k in range(1, n):
                noise[k] = a * noise[k - 1] + np.sqrt(1 - a * a) * noise[k]
        mount = m
        if thermal_arcsec and h == 1:
            mount = m * Rotation.from_rotvec(np.outer(np.sin(2 * np.pi * t / 5800), [thermal_arcsec * AS, 0, 0]))
        q = (body * mount * Rotation.from_rotvec(noise)).as_quat()  # scalar last
        out.append(HeadSeries(f"st{h + 1}", (T0 + np.round(t * 1e9)).astype(np.int64), np.roll(q, 1, axis=1),
                              np.roll(m.as_quat(), 1)))
    return out


def z_scores(runs, truth_arcsec) -> np.ndarray:  # noqa: ANN001
    return np.array([(r.sigma_rad / AS - np.asarray(truth_arcsec)) / (r.sigma_sigma_rad / AS) for r in runs])


def test_identical_heads_recover_the_sigmas_with_honest_uncertainty() -> None:
    runs = [analyze_heads(heads(s), MultiHeadSettings(identical_heads=True)) for s in range(20)]
    z = z_scores(runs, SAME)
    assert np.mean(np.abs(z) < 3) >= 0.95 and np.all(np.abs(z) < 4.5)
    assert np.all(np.std(z[:, 0], axis=0) < 1.4)  # sigma not too small
    assert sum(r.correlated for r in runs) <= 2
    assert sum(bool(multi_head_warnings(r)) for r in runs) <= 2  # clean data: no warning (false alarms)
    assert np.all([r.observable.all() for r in runs])


def test_three_heads_separate_every_head_and_axis() -> None:
    runs = [analyze_heads(heads(s, THREE, (M1, M2, M3))) for s in range(8)]
    z = z_scores(runs, THREE)
    assert np.mean(np.abs(z) < 3) >= 0.95
    assert all(r.observable.all() for r in runs) and len(runs[0].pairs) == 3


def test_unsynchronised_heads_are_interpolated() -> None:
    hs = heads(3, THREE, (M1, M2, M3), phases=(0.0, 0.5, 0.25))
    with pytest.raises(MultiHeadError, match="in common"):
        analyze_heads(hs)
    r = analyze_heads(hs, MultiHeadSettings(max_interpolation_s=1.5))
    assert all(p.n_interpolated > 0.9 * p.n_pairs for p in r.pairs)
    assert np.all(np.abs(z_scores([r], THREE)) < 3.5)


def test_two_heads_without_assumption_give_ranges_not_numbers() -> None:
    r = analyze_heads(heads(1, ((2, 4, 18), (5, 3, 25))))
    assert not r.observable.any() and np.isnan(r.sigma_rad).all()
    lo, hi = r.sigma_bounds_rad[..., 0] / AS, r.sigma_bounds_rad[..., 1] / AS
    assert np.all(lo <= hi) and np.all(hi[:, 2] - lo[:, 2] < 1.0)  # the boresight sigmas are nearly pinned
    assert np.all(np.abs(np.array([18, 25]) - (lo[:, 2] + hi[:, 2]) / 2) < 1.5)
    assert "not_observable" in {w.code for w in multi_head_warnings(r)}


def test_parallel_boresights_determine_only_the_boresight_axis() -> None:
    r = analyze_heads(heads(0, mounts=(M1, M1 * Rotation.from_euler("z", 90, degrees=True))),
                      MultiHeadSettings(identical_heads=True))
    assert r.observable.tolist() == [[False, False, True]] * 2
    assert abs(r.sigma_rad[0, 2] / AS - 18) < 3 * r.sigma_sigma_rad[0, 2] / AS


def test_correlated_noise_is_flagged() -> None:
    runs = [analyze_heads(heads(s, gm_tau_s=30.0), MultiHeadSettings(identical_heads=True)) for s in range(5)]
    assert all(r.correlated and r.inflation > 1.5 for r in runs)
    assert all("correlated_residuals" in {w.code for w in multi_head_warnings(r)} for r in runs)


def test_thermal_variation_is_removed_and_shown_in_the_boresight_angle() -> None:
    warm = analyze_heads(heads(2, n=5800, thermal_arcsec=20.0), MultiHeadSettings(identical_heads=True))
    cold = analyze_heads(heads(2, n=5800), MultiHeadSettings(identical_heads=True))
    assert np.all(np.abs(z_scores([warm], SAME)) < 3)
    assert warm.pairs[0].boresight_stats()["variation_peak_to_peak_rad"] > 5 * cold.pairs[0].boresight_stats()[
        "variation_peak_to_peak_rad"]
    cfg = np.degrees(warm.pairs[0].boresight_angle_configured_rad)
    assert abs(np.degrees(warm.pairs[0].boresight_stats()["mean_rad"]) - cfg) < 0.01


def test_a_conjugated_head_or_wrong_mounting_is_called_out() -> None:
    hs = heads(0)
    q = hs[1].q_IS.copy()
    q[:, 1:] *= -1
    r = analyze_heads([hs[0], HeadSeries("st2", hs[1].time_tai_ns, q, hs[1].q_BS)],
                      MultiHeadSettings(identical_heads=True))
    assert {"implausible_input", "correlated_residuals"} <= {w.code for w in multi_head_warnings(r)}
    wrong = HeadSeries("st2", hs[1].time_tai_ns, hs[1].q_IS, np.roll(M1.as_quat(), 1))
    r_wrong = analyze_heads([hs[0], wrong], MultiHeadSettings(identical_heads=True))
    codes = [w.code for w in multi_head_warnings(r_wrong)]
    assert "implausible_input" in codes


def test_different_heads_reject_the_identical_assumption() -> None:
    r = analyze_heads(heads(0, ((1, 2, 8), (6, 5, 30)), n=3600), MultiHeadSettings(identical_heads=True))
    assert any(w.code == "implausible_input" and "chi-square" in w.message for w in multi_head_warnings(r))


def test_errors() -> None:
    hs = heads(0)
    with pytest.raises(MultiHeadError, match="two heads"):
        analyze_heads(hs[:1])
    late = HeadSeries("st2", hs[1].time_tai_ns + 10**13, hs[1].q_IS, hs[1].q_BS)
    with pytest.raises(MultiHeadError, match="in common"):
        analyze_heads([hs[0], late])
    with pytest.raises(MultiHeadError):
        MultiHeadSettings(block_s=0)
