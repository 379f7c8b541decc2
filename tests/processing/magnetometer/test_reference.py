"""The reference |B| along the GNSS orbit (processing.magnetometer.reference) against IGRF-14 on the true orbit."""

from __future__ import annotations

import numpy as np

from processing.environment.igrf import igrf_field_E_nT
from processing.magnetometer.reference import reference_field_norm_nT
from processing.simulate.seed004 import simulate_seed004
from processing.time.timescales import iso_to_tai_ns

T0 = int(iso_to_tai_ns(["2025-03-20T12:00:00"])[0])


def _xyz(c: dict, names: str) -> np.ndarray:
    return np.column_stack([c[k] for k in names.split()])


def test_spline_nodes_match_the_synthesis_and_gaps_are_masked() -> None:
    sc = simulate_seed004(start_tai_ns=T0, duration_s=1200.0, seed=1, controller="none", estimator="truth",
                          gnss_position_noise_m=0.0, gnss_velocity_noise_m_s=0.0)
    m, g = sc.streams["magnetometer"], sc.streams["gnss"]
    truth = np.linalg.norm(igrf_field_E_nT(sc.truth.r_E, sc.truth.time_tai_ns), axis=1)
    for step in (10.0, 0.0):
        ref, ok = reference_field_norm_nT(m["time_tai_ns"], g["time_tai_ns"], _xyz(g, "x y z"), _xyz(g, "vx vy vz"),
                                          field_step_s=step)
        assert ok.all() and np.max(np.abs(ref - truth)) < 0.01  # nT
    keep = np.ones(g["time_tai_ns"].size, dtype=bool)
    keep[300:500] = False  # a 201 s GNSS gap
    ref, ok = reference_field_norm_nT(m["time_tai_ns"][5:], g["time_tai_ns"][keep], _xyz(g, "x y z")[keep],
                                      _xyz(g, "vx vy vz")[keep], max_gnss_gap_s=120.0)
    k = np.arange(5, truth.size)  # masked: [last GNSS sample before the gap, first after)
    assert np.array_equal(~ok, (k >= 299) & (k < 500))
    assert np.all(np.isnan(ref[~ok])) and np.max(np.abs(ref[ok] - truth[5:][ok])) < 0.05
