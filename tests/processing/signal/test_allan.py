"""Allan deviation and IEEE 952 noise terms (processing.signal.allan) on simulated gyro noise
(processing.simulate.definitive.gyro_noise_rates): the terms come back inside their 95 % intervals."""

from __future__ import annotations

import numpy as np
import pytest

from processing.signal.allan import AllanError, allan_deviation, fit_noise
from processing.simulate.definitive import gyro_noise_rates
from processing.units import RAD_PER_DEG, RAD_S_PER_DEG_H

ARW = 0.05 * RAD_PER_DEG / 60.0  # 0.05 deg/sqrt(h) in rad/sqrt(s)
BI = 0.5 * RAD_S_PER_DEG_H  # 0.5 deg/h
RRW = 4e-7  # rad/s/sqrt(s): dominant beyond ~1000 s
RATE_HZ = 10.0


@pytest.fixture(scope="module")
def fits():
    out = []
    for seed in range(6):
        x = gyro_noise_rates(200_000, 1 / RATE_HZ, arw_rad_sqrt_s=ARW, bias_instability_rad_s=BI,
                             rate_random_walk_rad_s_sqrt_s=RRW, seed=seed)
        out.append(fit_noise(allan_deviation(x, RATE_HZ)))
    return out


def test_terms_recovered_within_their_confidence_intervals(fits):
    for name, truth in (("angle_random_walk", ARW), ("bias_instability", BI), ("rate_random_walk", RRW)):
        inside = np.concatenate([(f.terms[name].lo <= truth) & (truth <= f.terms[name].hi) for f, _ in fits])
        det = np.concatenate([f.terms[name].determined for f, _ in fits])
        assert inside.mean() >= 0.8, (name, inside.mean())
        assert det.mean() >= 0.8, (name, det.mean())
    arw = np.concatenate([f.terms["angle_random_walk"].value for f, _ in fits])
    np.testing.assert_allclose(arw, ARW, rtol=0.02)
    assert not any(f.terms["angle_white_noise"].determined.any() for f, _ in fits)


def test_deviation_bounds_and_model(fits):
    fit, ad = fits[0]
    assert np.all(ad.lo <= ad.adev) and np.all(ad.adev <= ad.hi)
    assert np.all(fit.chi2_per_dof < 4.0)
    inside = (ad.lo <= fit.model_adev) & (fit.model_adev <= ad.hi)
    assert inside.mean() > 0.85


def test_flicker_floor_is_0664_b():
    """The simulator's flicker scaling (Kasdin filter, Q = B²) gives the IEEE 952 floor 0.664 B."""
    x = gyro_noise_rates(400_000, 1.0, bias_instability_rad_s=BI, seed=3)
    ad = allan_deviation(x, 1.0)
    mid = (ad.tau_s >= 16) & (ad.tau_s <= 4096)
    ratio = ad.adev[mid] / (np.sqrt(2 * np.log(2) / np.pi) * BI)
    assert 0.85 < float(np.median(ratio)) < 1.15


def test_white_noise_only_leaves_bi_and_rrw_undetermined():
    x = gyro_noise_rates(100_000, 0.1, arw_rad_sqrt_s=ARW, seed=8)
    fit, _ = fit_noise(allan_deviation(x, 10.0))
    assert fit.terms["angle_random_walk"].determined.all()
    assert not fit.terms["rate_random_walk"].determined.any()
    assert np.all(np.isnan(fit.terms["rate_random_walk"].value))
    assert np.all(fit.terms["bias_instability"].hi < 0.5 * BI)


def test_angles_with_gaps_white_angle_noise_and_arw():
    """Gyro-minus-star-tracker angles: white angle noise Q plus the integrated ARW, with missing samples."""
    rng = np.random.default_rng(4)
    n, q = 40_000, 5e-6
    angle = np.cumsum(gyro_noise_rates(n, 1.0, arw_rad_sqrt_s=ARW, seed=9), axis=0) + rng.standard_normal((n, 3)) * q
    angle[1000:1200] = np.nan
    ad = allan_deviation(angle, 1.0, kind="angles")
    fit, _ = fit_noise(ad)
    for name, truth in (("angle_white_noise", q), ("angle_random_walk", ARW)):
        t = fit.terms[name]
        assert t.determined.all() and np.all((t.lo <= truth * 1.05) & (truth * 0.95 <= t.hi)), (name, t)


def test_bad_input():
    with pytest.raises(AllanError):
        allan_deviation(np.zeros((5, 3)), 1.0)
    with pytest.raises(AllanError):
        allan_deviation(np.full((100, 3), np.nan), 1.0, kind="rates")
