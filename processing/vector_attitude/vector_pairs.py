"""The vector pairs of paper 002 per epoch, from the telemetry streams (steps before the solvers of
:mod:`processing.vector_attitude.determination`).

Holds the typed options (:class:`VectorAttitudeParams`), the pairs (:class:`Observations`: body and orbital
unit vectors of the antenna axis, the magnetic field and the Sun with their direction sigmas and why a
vector is missing) and their assembly (:func:`observations`): the epochs, the GNSS track, the magnetometer
against IGRF-14 or 002's axial dipole (:func:`dipole_field_O`), the sun vector from the panel currents, the
antenna axis from the visibility of the navigation satellites. The error model is described in
:mod:`processing.vector_attitude.determination`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.environment.dipole import dipole_field_O002_nT
from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp
from processing.orbits.gnss_ephemeris import satellite_positions_E
from processing.screening.base import Environment, ScreeningResult
from processing.screening.gnss import GnssTrack
from processing.screening.panels import pivot, sun_from_currents
from processing.screening.tools import hermite_state
from processing.spacecraft import Spacecraft
from processing.units import NS_PER_S, OMEGA_EARTH_RAD_S
from processing.vector_attitude.antenna_axis import (
    DEFAULT_CONE_HALF_ANGLE_RAD,
    DEFAULT_GRAZING_ALTITUDE_M,
    antenna_axis_O,
    dcm_EO_002,
    earth_occulted,
    line_of_sight_O,
    refine_antenna_axis_O,
)

VECTORS = ("antenna", "magnetometer", "sun")
METHODS = ("auto", "q_method", "quest", "svd", "esoq2", "loosely_coupled")
Method = Literal["auto", "q_method", "quest", "svd", "esoq2", "loosely_coupled"]


class VectorAttitudeError(ValueError):
    """The inputs do not allow any attitude (no orbit, no vectors); the message says what is missing."""


@dataclass(frozen=True)
class VectorAttitudeParams:
    """Options of :func:`vector_attitude` (see the module docstring for the error model).

    weights: a_i per vector name (antenna, magnetometer, sun); None: 1 / sigma_i^2.
    antenna_method: "eq7" (the paper's least squares) or "cone" (eq. 7 refined by the maximum-likelihood
    cone fit of :func:`processing.vector_attitude.antenna_axis.refine_antenna_axis_O`, the default).
    """

    method: Method = "auto"
    weights: Mapping[str, float] | None = None
    field_model: Literal["igrf", "dipole"] = "igrf"
    magnetometer_noise_nT: float = 100.0
    field_model_error_nT: float = 150.0
    current_noise_a: float = 0.02
    current_model_error_a: float = 0.02
    antenna_sigma_deg: float = 8.0
    antenna_method: Literal["eq7", "cone"] = "cone"
    cone_half_angle_deg: float | None = None
    """Half-angle of the antenna cone (eq. 5), deg; None: 80 deg (DEFAULT_CONE_HALF_ANGLE_RAD)."""
    grazing_altitude_m: float = DEFAULT_GRAZING_ALTITUDE_M
    max_time_offset_s: float = 0.6
    max_interpolation_gap_s: float = 30.0
    sun_norm_tolerance: float = 0.15


@dataclass(frozen=True)
class Observations:
    """Vector pairs per epoch: b_B, r_O (T, 3, 3) unit, axis 1 in VECTORS order; available (T, 3);
    sigma_rad (T, 3); why (T, 3) str: reason a vector is missing ("" when available)."""

    time_tai_ns: NDArray[np.int64]
    b_B: NDArray[np.float64]
    r_O: NDArray[np.float64]
    available: NDArray[np.bool_]
    sigma_rad: NDArray[np.float64]
    why: NDArray[np.object_]
    r_E: NDArray[np.float64]
    v_E: NDArray[np.float64]
    antenna_violations: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))


def _match(t_epochs: NDArray[np.int64], t_samples: NDArray[np.int64], tol_s: float) -> NDArray[np.int64]:
    """Index of the nearest sample (sorted t_samples) to each epoch within tol_s, else -1."""
    if t_samples.size == 0:
        return np.full(t_epochs.size, -1, dtype=np.int64)
    k = np.clip(np.searchsorted(t_samples, t_epochs), 1, max(1, t_samples.size - 1))
    if t_samples.size == 1:
        k = np.zeros(t_epochs.size, dtype=np.int64)
        best = k
    else:
        left = k - 1
        best = np.where(np.abs(t_epochs - t_samples[left]) <= np.abs(t_samples[k] - t_epochs), left, k)
    ok = np.abs(t_samples[best] - t_epochs) <= tol_s * NS_PER_S
    return np.where(ok, best, -1)


def _accepted(screening: ScreeningResult | None, stream: str, n: int) -> NDArray[np.bool_]:
    if screening is None or stream not in screening.n_rows:
        return np.ones(n, dtype=bool)
    return ~screening.rejected(stream)


def _unit(x: NDArray[np.float64]) -> NDArray[np.float64]:
    with np.errstate(invalid="ignore", divide="ignore"):
        return x / np.linalg.norm(x, axis=-1, keepdims=True)


def observations(streams: Mapping[str, Mapping[str, NDArray[Any]]], spacecraft: Spacecraft,
                 params: VectorAttitudeParams | None = None, *, nav: Mapping[str, Any] | None = None,
                 screening: ScreeningResult | None = None, env: Environment | None = None,
                 time_tai_ns: ArrayLike | None = None) -> Observations:
    """Body and orbital vectors at each epoch from the streams (rows rejected by ``screening`` unused).

    Epochs: ``time_tai_ns`` if given, else the magnetometer times, else the panel-current times, else
    the visibility times. The orbit comes from the GNSS stream (accepted rows, cubic Hermite); nav
    (rinex_nav columns) is needed for the antenna vector. The mountings come from ``spacecraft``
    (magnetometer q_BM, solar panels, antenna axis): a stream whose sensor is not configured raises
    MissingMountingError.
    """
    p = params or VectorAttitudeParams()
    env = env or Environment()
    track = _track(streams, screening)
    t = _epochs(streams, time_tai_ns)
    r_E, v_E = hermite_state(track.time_tai_ns, track.r_E, track.v_E, t, p.max_interpolation_gap_s)
    acc = _Accumulator.empty(t, r_E, v_E)
    _magnetometer(acc, streams.get("magnetometer"), spacecraft, p, screening, env)
    if "panel_currents" in streams and len(streams["panel_currents"]["time_tai_ns"]) and spacecraft.solar_panels:
        _sun(acc, streams["panel_currents"], spacecraft, p, screening, env)
    else:
        acc.why[acc.have_orbit, 2] = "no panel currents or no solar_panels configuration"
    violations = _antenna(acc, streams.get("gnss_visibility"), spacecraft, track, p, nav, screening)
    available = np.isfinite(acc.b_B).all(axis=2) & np.isfinite(acc.r_O).all(axis=2) & np.isfinite(acc.sigma)
    return Observations(time_tai_ns=t, b_B=acc.b_B, r_O=acc.r_O, available=available, sigma_rad=acc.sigma,
                        why=acc.why, r_E=r_E, v_E=v_E, antenna_violations=violations)


def _track(streams: Mapping[str, Mapping[str, NDArray[Any]]], screening: ScreeningResult | None) -> GnssTrack:
    """The accepted GNSS states in time order (the orbit of the orbital frame and the models)."""
    if "gnss" not in streams or len(streams["gnss"]["time_tai_ns"]) < 2:
        raise VectorAttitudeError("vector attitude needs the GNSS stream (the orbital frame and the models)")
    g = streams["gnss"]
    g_ok = _accepted(screening, "gnss", len(g["time_tai_ns"]))
    order = np.argsort(np.asarray(g["time_tai_ns"], dtype=np.int64)[g_ok], kind="stable")
    tg = np.asarray(g["time_tai_ns"], dtype=np.int64)[g_ok][order]
    return GnssTrack(tg, np.stack([np.asarray(g[c], float)[g_ok][order] for c in ("x", "y", "z")], axis=1),
                     np.stack([np.asarray(g[c], float)[g_ok][order] for c in ("vx", "vy", "vz")], axis=1))


def _epochs(streams: Mapping[str, Mapping[str, NDArray[Any]]], time_tai_ns: ArrayLike | None) -> NDArray[np.int64]:
    if time_tai_ns is not None:
        return np.asarray(time_tai_ns, dtype=np.int64)
    for name in ("magnetometer", "panel_currents", "gnss_visibility"):
        if name in streams and len(streams[name]["time_tai_ns"]):
            return np.unique(np.asarray(streams[name]["time_tai_ns"], dtype=np.int64))
    raise VectorAttitudeError("no magnetometer, panel_currents or gnss_visibility samples in the window")


@dataclass(frozen=True, eq=False)
class _Accumulator:
    """The vector pairs being filled in, per epoch: t (T,), the orbit r_E, v_E (T, 3) with have_orbit,
    dcm_EO (T, 3, 3) (a placeholder orbit where there is none), b_B, r_O (T, 3, 3), sigma (T, 3), why (T, 3)."""

    t: NDArray[np.int64]
    r_E: NDArray[np.float64]
    v_E: NDArray[np.float64]
    have_orbit: NDArray[np.bool_]
    dcm_EO: NDArray[np.float64]
    b_B: NDArray[np.float64]
    r_O: NDArray[np.float64]
    sigma: NDArray[np.float64]
    why: NDArray[np.object_]

    @classmethod
    def empty(cls, t: NDArray[np.int64], r_E: NDArray[np.float64], v_E: NDArray[np.float64]) -> _Accumulator:
        n = t.size
        have_orbit = np.asarray(np.isfinite(r_E).all(axis=1), dtype=np.bool_)
        r_safe = np.where(have_orbit[:, None], r_E, [7e6, 0.0, 0.0])
        v_safe = np.where(have_orbit[:, None], v_E, [0.0, 7.5e3, 0.0])
        why = np.full((n, 3), "", dtype=object)
        why[~have_orbit, :] = "no GNSS orbit"
        return cls(t=t, r_E=r_E, v_E=v_E, have_orbit=have_orbit, dcm_EO=dcm_EO_002(r_safe, v_safe),
                   b_B=np.full((n, 3, 3), np.nan), r_O=np.full((n, 3, 3), np.nan), sigma=np.full((n, 3), np.nan),
                   why=why)


def _magnetometer(acc: _Accumulator, m: Mapping[str, NDArray[Any]] | None, spacecraft: Spacecraft,
                  p: VectorAttitudeParams, screening: ScreeningResult | None, env: Environment) -> None:
    """h_B = R(q_BM) h_M against the model field in O (IGRF-14 or the dipole of eq. 2), column 1."""
    if m is None or not len(m["time_tai_ns"]):
        acc.why[acc.have_orbit, 1] = "no magnetometer stream"
        return
    t, have_orbit = acc.t, acc.have_orbit
    ok_rows = _accepted(screening, "magnetometer", len(m["time_tai_ns"]))
    tm = np.asarray(m["time_tai_ns"], dtype=np.int64)
    o = np.argsort(tm, kind="stable")
    k = _match(t, tm[o], p.max_time_offset_s)
    rows = np.where(k >= 0, o[np.maximum(k, 0)], -1)
    h_M = np.stack([np.asarray(m[c], float) for c in ("bx", "by", "bz")], axis=1)
    h_B = rotations.quat_rotate(spacecraft.magnetometer_mounting(), h_M)
    present = rows >= 0
    accepted = present & ok_rows[np.maximum(rows, 0)]
    use = accepted & have_orbit
    if np.any(use):
        if p.field_model == "dipole":
            B_O = dipole_field_O(acc.r_E[use], acc.v_E[use])
        else:
            B_O = np.einsum("nji,nj->ni", acc.dcm_EO[use], env.field_E_nT(acc.r_E[use], t[use]))
        acc.b_B[use, 1] = _unit(h_B[rows[use]])
        acc.r_O[use, 1] = _unit(B_O)
        acc.sigma[use, 1] = np.hypot(p.magnetometer_noise_nT, p.field_model_error_nT) / np.linalg.norm(B_O, axis=1)
    acc.why[~present & have_orbit, 1] = "no magnetometer sample"
    acc.why[present & ~accepted & have_orbit, 1] = "magnetometer sample rejected"


def _sun(acc: _Accumulator, pc: Mapping[str, NDArray[Any]], spacecraft: Spacecraft, p: VectorAttitudeParams,
         screening: ScreeningResult | None, env: Environment) -> None:
    """The sun vector from the panel currents (I = I_max max(0, n . s)) in full sunlight, column 2."""
    t, have_orbit, n = acc.t, acc.have_orbit, acc.t.size
    normals, imax = spacecraft.panel_normals_B(), spacecraft.panel_max_current_a()
    ok_rows = _accepted(screening, "panel_currents", len(pc["time_tai_ns"]))
    epochs, keys, index = pivot(np.asarray(pc["time_tai_ns"], dtype=np.int64), np.asarray(pc["panel"], dtype=np.int64))
    valid_keys = (keys >= 0) & (keys < imax.size)
    keys, index = keys[valid_keys], index[:, valid_keys]
    cur = np.full(index.shape, np.nan)
    cur[index >= 0] = np.where(ok_rows[index[index >= 0]], np.asarray(pc["current_a"], float)[index[index >= 0]],
                               np.nan)
    complete = np.isfinite(cur).all(axis=1) & (keys.size == imax.size)
    s_raw, determined = sun_from_currents(cur, normals[keys], imax[keys], lit_threshold_a=p.current_noise_a * 3)
    k = _match(t, epochs, p.max_time_offset_s)
    present = k >= 0
    kk = np.maximum(k, 0)
    r_I_sun = env.sun_position_I_m(t)
    use0 = present & have_orbit
    nu = np.full(n, np.nan)
    s_O = np.full((n, 3), np.nan)
    if np.any(use0):
        m_EI = gcrs_to_itrs_mat_interp(t[use0])
        r_I = np.einsum("nji,nj->ni", m_EI, acc.r_E[use0])
        nu[use0] = env.sunlit_fraction(r_I, r_I_sun[use0])
        s_E = np.einsum("nij,nj->ni", m_EI, _unit(r_I_sun[use0] - r_I))
        s_O[use0] = np.einsum("nji,nj->ni", acc.dcm_EO[use0], s_E)
    consistent = np.abs(np.linalg.norm(s_raw, axis=1) - 1.0) <= p.sun_norm_tolerance
    sunlit = np.nan_to_num(nu) >= 1.0
    use = use0 & sunlit & complete[kk] & determined[kk] & consistent[kk]
    acc.b_B[use, 2] = _unit(s_raw[kk[use]])
    acc.r_O[use, 2] = s_O[use]
    acc.sigma[use, 2] = (p.current_noise_a + p.current_model_error_a) / float(np.min(imax))
    acc.why[~present & have_orbit, 2] = "no panel currents"
    acc.why[use0 & ~sunlit, 2] = "Earth shadow"
    acc.why[use0 & sunlit & ~complete[kk], 2] = "panel current missing or rejected"
    acc.why[use0 & sunlit & complete[kk] & ~(determined[kk] & consistent[kk]), 2] = "currents do not determine the sun"


def _antenna(acc: _Accumulator, vis: Mapping[str, NDArray[Any]] | None, spacecraft: Spacecraft, track: GnssTrack,
             p: VectorAttitudeParams, nav: Mapping[str, Any] | None,
             screening: ScreeningResult | None) -> NDArray[np.float64]:
    """The antenna axis: a_B configured, a_O from the visibility (eqs. 5-7), column 0. Returns the
    number of cone violations per epoch (NaN where not computed)."""
    t, have_orbit = acc.t, acc.have_orbit
    violations = np.full(t.size, np.nan)
    if nav is None:
        acc.why[have_orbit, 0] = "no navigation data (rinex_nav)"
        return violations
    if vis is None or not len(vis["time_tai_ns"]):
        acc.why[have_orbit, 0] = "no gnss_visibility stream"
        return violations
    tv = np.asarray(vis["time_tai_ns"], dtype=np.int64)
    v_epochs = np.unique(tv)
    k = _match(t, v_epochs, p.max_time_offset_s)
    present = (k >= 0) & have_orbit
    if np.any(present):
        a_B = spacecraft.antenna_axis_B()
        ve, inv = np.unique(v_epochs[k[present]], return_inverse=True)
        a_O, good_u, n_violations = _antenna_axis_O(vis, tv, ve, track, p, nav, screening)
        idx = np.flatnonzero(present)
        good = good_u[inv]
        acc.b_B[idx[good], 0] = _unit(a_B)
        acc.r_O[idx[good], 0] = a_O[inv][good]
        acc.sigma[idx[good], 0] = np.deg2rad(p.antenna_sigma_deg)
        violations[idx] = n_violations[inv]
        acc.why[idx[~good], 0] = "too few navigation satellites for the antenna axis"
    acc.why[(k < 0) & have_orbit, 0] = "no visibility report"
    return violations


def _antenna_axis_O(vis: Mapping[str, NDArray[Any]], tv: NDArray[np.int64], ve: NDArray[np.int64], track: GnssTrack,
                    p: VectorAttitudeParams, nav: Mapping[str, Any], screening: ScreeningResult | None
                    ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.int64]]:
    """a_O (E, 3) at the visibility epochs ve (E,) from the tracked satellites (002 eqs. 5-7, refined by
    the cone fit with antenna_method "cone"), whether it was determined (E,), and the cone violations."""
    ok_rows = _accepted(screening, "gnss_visibility", len(tv))
    sat = np.array([f"{s}{int(x):02d}" for s, x in zip(np.asarray(vis["system"]), np.asarray(vis["prn"]),
                                                       strict=True)])
    visible = np.asarray(vis["visible"], dtype=bool) & ok_rows
    systems = sorted({s[0] for s in sat})
    names = sorted({str(s) for s in np.asarray(nav["sat"]).astype(str) if s[0] in systems})
    pos = satellite_positions_E(nav, ve, names)
    rv, vv = hermite_state(track.time_tai_ns, track.r_E, track.v_E, ve, p.max_interpolation_gap_s)
    good_orbit = np.asarray(np.isfinite(rv).all(axis=1), dtype=np.bool_)
    known = pos.valid & good_orbit[:, None]
    rv = np.where(good_orbit[:, None], rv, [7e6, 0.0, 0.0])
    vv = np.where(good_orbit[:, None], vv, [0.0, 7.5e3, 0.0])
    los = line_of_sight_O(pos.r_E, rv, dcm_EO_002(rv, vv))
    name_idx = {s: i for i, s in enumerate(names)}
    row_epoch = np.searchsorted(ve, tv)
    in_window = (row_epoch < ve.size) & (ve[np.minimum(row_epoch, ve.size - 1)] == tv)
    sel = in_window & visible & np.isin(sat, names)
    vis_mat = np.zeros((ve.size, len(names)), bool)
    vis_mat[row_epoch[sel], [name_idx[s] for s in sat[sel]]] = True
    cone = DEFAULT_CONE_HALF_ANGLE_RAD if p.cone_half_angle_deg is None else np.deg2rad(p.cone_half_angle_deg)
    radius = np.linalg.norm(rv, axis=1)
    res = antenna_axis_O(los, vis_mat, known, radius, cone_half_angle_rad=cone, grazing_altitude_m=p.grazing_altitude_m)
    a_O = res.a_O
    if p.antenna_method == "cone":
        occ = earth_occulted(los, radius, p.grazing_altitude_m)
        a_O = refine_antenna_axis_O(los, vis_mat, known & (vis_mat | ~occ), a_O, cone)
    return a_O, res.ok & np.isfinite(a_O).all(axis=1), res.n_violations


def dipole_field_O(r_E: ArrayLike, v_E: ArrayLike) -> NDArray[np.float64]:
    """002 eq. 2 (axial dipole, processing.environment.dipole) in the orbital frame of 002, nT.

    The inclination i and argument of latitude u are those of the osculating orbit relative to the
    Earth's axis (the ITRF z axis), from r_E and the inertial velocity v_E + w x r_E; exact for the
    axial dipole whatever the orbit's node. r_E, v_E: (N, 3) m, m/s ITRF.
    """
    r = np.asarray(r_E, dtype=np.float64)
    v = np.asarray(v_E, dtype=np.float64) + np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r)
    h = np.cross(r, v)
    h_unit = _unit(h)
    inc = np.arccos(np.clip(h_unit[:, 2], -1.0, 1.0))
    node = _unit(np.stack([-h[:, 1], h[:, 0], np.zeros(len(h))], axis=1))  # z x h
    u = np.arctan2(np.sum(r * np.cross(h_unit, node), axis=1), np.sum(r * node, axis=1))
    return dipole_field_O002_nT(np.linalg.norm(r, axis=1), inc, u)

