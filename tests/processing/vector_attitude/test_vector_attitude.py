"""Vector attitude (002 figure 1, eqs. 5-14): error against truth vs the noise bound, and the algorithm
selection when streams are missing or rejected."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from processing.attitude import rotations
from processing.formats.rinex_nav import parse_rinex_nav
from processing.screening import criteria as screening
from processing.simulate.seed002 import simulate_seed002
from processing.spacecraft import MissingMountingError, Spacecraft
from processing.vector_attitude import determination as va
from tests.real_data import GNSS_NAV

NAV = GNSS_NAV / "brdc2800.15n"
# The error model of the scenario: 100 nT magnetometer noise and the same IGRF in truth and model;
# 0.01 A current noise; the antenna axis from visibility (GPS only, 80 deg cone) has ~8 deg per axis.
SCENARIO_PARAMS = va.VectorAttitudeParams(field_model_error_nT=0.0, current_noise_a=0.01, current_model_error_a=0.0,
                                          antenna_sigma_deg=8.0)


@cache
def nav():
    return parse_rinex_nav(NAV.read_bytes()).columns


@cache
def scenario(seed: int, duration_s: float):
    sc = simulate_seed002(nav=nav(), seed=seed, duration_s=duration_s)
    return sc, screening.screen(sc.streams, Spacecraft.from_json(sc.config), nav=nav())


@cache
def observed(seed: int = 5, duration_s: float = 5800.0):
    sc, scr = scenario(seed, duration_s)
    return sc, va.observations(sc.streams, Spacecraft.from_json(sc.config), SCENARIO_PARAMS, nav=nav(),
                               screening=scr)


def solved(method: str = "auto"):
    sc, obs = observed()
    p = va.VectorAttitudeParams(**{**SCENARIO_PARAMS.__dict__, "method": method})
    return sc, obs, va.vector_attitude(obs, p)


def test_error_consistent_with_the_noise_bound() -> None:
    """Bound: the error rotation d (body frame) ~ N(0, P) with P the sandwich covariance of the vector
    noise (module docstring), so |d| <= sqrt(chi2_3(0.99) lambda_max(P)) for 99 % of epochs and the mean
    NEES d^T P^-1 d is 3. Tested over one orbit (seed 5): strongly coupled epochs (three vectors) within
    the bound >= 98 % with mean NEES in [1.5, 4.5] and a median error below 1 deg; two-vector epochs
    (eclipse: magnetometer + antenna) within the bound >= 97 %."""
    sc, obs, res = solved()
    err, nees = va.attitude_errors(res, sc.truth.q_OB)
    bound = res.bound_rad()
    three = res.used.sum(axis=1) == 3
    two = res.used.sum(axis=1) == 2
    assert three.sum() > 2000 and two.sum() > 1500
    assert np.all(res.method[three] == "q_method")
    assert np.median(np.degrees(err[three])) < 1.0
    assert np.mean(err[three] <= bound[three]) >= 0.98
    assert 1.5 <= np.mean(nees[three]) <= 4.5
    assert np.mean(err[two] <= bound[two]) >= 0.97
    assert np.mean(nees[two]) <= 4.5
    assert res.ok.mean() > 0.99


def test_wahba_methods_agree_on_the_scenario() -> None:
    _, _, ref = solved(method="q_method")
    three = ref.used.sum(axis=1) == 3
    for m in ("quest", "svd", "esoq2"):
        _, _, res = solved(method=m)
        assert np.all(res.method[ref.ok] == m)
        assert np.max(rotations.angle_between(res.q_OB[three], ref.q_OB[three])) < 1e-8


def test_select_methods_truth_table() -> None:
    av = np.array([[1, 1, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], bool)
    assert va.select_methods(av).tolist() == ["q_method", "loosely_coupled", "q_method", "q_method", "none", "none",
                                              "none", "none"]
    assert va.select_methods(av, "quest").tolist()[:4] == ["quest"] * 4
    assert va.select_methods(av, "loosely_coupled").tolist()[:4] == ["loosely_coupled", "loosely_coupled", "none",
                                                                     "none"]
    with pytest.raises(va.VectorAttitudeError, match="unknown method"):
        va.select_methods(av, "triad")


def _run(streams, config, seed: int = 2, duration_s: float = 1800.0, method: str = "auto"):
    sc, _ = scenario(seed, duration_s)
    p = va.VectorAttitudeParams(**{**SCENARIO_PARAMS.__dict__, "method": method})
    scr = screening.screen(streams, Spacecraft.from_json(config), nav=nav())
    obs = va.observations(streams, Spacecraft.from_json(config), p, nav=nav(), screening=scr)
    return sc, obs, va.vector_attitude(obs, p)


def test_selection_when_streams_are_missing() -> None:
    """Figure 1 with streams removed: the 1800 s segment is sunlit, then in the Earth's shadow."""
    sc, _ = scenario(2, 1800.0)
    lit = sc.truth.sunlit_fraction >= 1.0
    shadow = sc.truth.sunlit_fraction == 0.0
    assert lit.sum() > 600 and shadow.sum() > 300
    full = dict(sc.streams)
    # no panel currents: magnetometer + antenna everywhere -> loosely coupled
    _, obs, res = _run({k: v for k, v in full.items() if k != "panel_currents"}, sc.config)
    assert not obs.available[:, 2].any() and set(obs.why[:, 2]) == {"no panel currents or no solar_panels "
                                                                   "configuration"}
    assert np.mean(res.method == "loosely_coupled") > 0.98
    # no visibility: magnetometer + sun in sunlight (two-vector q-method), nothing in the shadow
    _, obs, res = _run({k: v for k, v in full.items() if k != "gnss_visibility"}, sc.config)
    assert np.mean(res.method[lit] == "q_method") > 0.95 and np.all(res.used[lit & res.ok, 0] == 0)
    assert np.all(res.method[shadow] == "none")
    assert all("sun: Earth shadow" in r and "antenna: no gnss_visibility stream" in r for r in res.reason[shadow])
    # no magnetometer: antenna + sun in sunlight, nothing in the shadow
    _, obs, res = _run({k: v for k, v in full.items() if k != "magnetometer"}, sc.config)
    assert np.mean(res.method[lit] == "q_method") > 0.95 and np.all(res.method[shadow] == "none")
    # no navigation data: no antenna vector
    p = SCENARIO_PARAMS
    obs = va.observations(full, Spacecraft.from_json(sc.config), p, nav=None)
    assert not obs.available[:, 0].any() and obs.why[0, 0] == "no navigation data (rinex_nav)"
    # no GNSS: no orbital frame, no models
    with pytest.raises(va.VectorAttitudeError, match="needs the GNSS stream"):
        va.observations({k: v for k, v in full.items() if k != "gnss"}, Spacecraft.from_json(sc.config), p,
                        nav=nav())


def test_rejected_samples_are_not_used() -> None:
    """Epochs whose magnetometer sample was rejected (spikes) do not use the magnetometer; in the
    shadow they fall back to no attitude (antenna only), in sunlight to antenna + sun."""
    sc, obs, res = solved()
    t = sc.truth
    spike_t = t.time_tai_ns[t.faults["magnetometer"]]
    k = np.searchsorted(res.time_tai_ns, spike_t)
    assert k.size > 20
    assert not res.used[k, 1].any() and np.all(obs.why[k, 1] == "magnetometer sample rejected")
    lit = t.sunlit_fraction[k] >= 1.0
    assert np.all(res.method[k[~lit]] == "none")
    assert np.mean(res.method[k[lit]] == "q_method") > 0.8
    # without the screening the spikes enter the solution, whose error then breaks the noise bound
    p = SCENARIO_PARAMS
    raw = va.vector_attitude(va.observations(sc.streams, Spacecraft.from_json(sc.config), p, nav=nav()), p)
    err_raw, _ = va.attitude_errors(raw, t.q_OB)
    assert raw.used[k, 1].all()
    assert np.mean(err_raw[k] > raw.bound_rad()[k]) > 0.5
    err, _ = va.attitude_errors(res, t.q_OB)
    ok = np.isfinite(err[k])
    assert np.mean(err[k][ok] <= res.bound_rad()[k][ok]) > 0.9


def test_dipole_field_model_of_eq2() -> None:
    """002 eq. 2 in O is within ~20 deg of IGRF-14 along the orbit; the attitude from it is as coarse."""
    sc, obs = observed()
    p = va.VectorAttitudeParams(**{**SCENARIO_PARAMS.__dict__, "field_model": "dipole",
                                   "field_model_error_nT": 4000.0})
    obs_d = va.observations(sc.streams, Spacecraft.from_json(sc.config), p, nav=nav(),
                            time_tai_ns=obs.time_tai_ns[::20])
    igrf = obs.r_O[::20, 1]
    both = np.isfinite(obs_d.r_O[:, 1]).all(axis=1) & np.isfinite(igrf).all(axis=1)
    ang = np.degrees(np.arccos(np.clip(np.sum(obs_d.r_O[both, 1] * igrf[both], axis=1), -1, 1)))
    assert 2.0 < np.median(ang) < 20.0 and np.max(ang) < 30.0
    res = va.vector_attitude(obs_d, p)
    err, _ = va.attitude_errors(res, sc.truth.q_OB[::20])
    assert 0.5 < np.nanmedian(np.degrees(err)) < 20.0


@pytest.mark.parametrize("key, sensor", [("magnetometer", "the magnetometer"),
                                         ("gnss_antenna_axis_B", "the GNSS antenna axis")])
def test_a_vector_without_its_mounting_is_an_error_naming_the_sensor(key: str, sensor: str) -> None:
    """No identity q_BM and no [1, 0, 0] antenna axis when the configuration lacks them."""
    sc, _ = scenario(2, 1800.0)
    config = Spacecraft.from_json({k: v for k, v in sc.config.items() if k != key})
    with pytest.raises(MissingMountingError, match=f"{sensor} is not in the spacecraft configuration"):
        va.observations(sc.streams, config, SCENARIO_PARAMS, nav=nav())
