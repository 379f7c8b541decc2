"""Positions of navigation satellites from broadcast ephemerides (002: "ephemerides of the invisible
satellites from the interface control documents", refs. 3-4).

- GPS, QZSS, Galileo, BeiDou, IRNSS (Keplerian broadcast orbits): the user algorithm of IS-GPS-200
  (rev. N, table 20-IV: mean anomaly, Kepler's equation, second-harmonic corrections, rotation to
  Earth-fixed coordinates); Galileo OS SIS ICD §5.1.1 and BeiDou OS SIS ICD §5.2.4 are the same
  algorithm with their own GM (BeiDou GEO satellites with the extra -5 deg rotation of the BeiDou ICD).
- GLONASS and SBAS (state vectors): numerical integration of the equations of motion of the GLONASS
  ICD (ed. 5.1, A.3.1.2) in the Earth-fixed PZ-90 frame: central field, J2, centrifugal and Coriolis
  terms, the broadcast luni-solar accelerations held constant; classical RK4 with a 30 s step from tb,
  cubic Hermite interpolation between steps (interpolation error < 1 mm).

Earth-fixed frames: WGS 84 (GPS), PZ-90.11 (GLONASS), GTRF, CGCS2000 agree with the ITRF to a few
decimetres, far below what the visibility geometry of 002 needs; all results are called ITRF (E).
Times are int64 tai_ns; each system's scale is handled through the record times of
:mod:`processing.formats.rinex_nav` (absolute TAI instants), so week crossovers need no special case.
The satellite position is evaluated at the given instant (no light-time correction: ~70 ms of flight
move a GPS satellite by ~270 m, 1e-5 rad seen from LEO).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.orbits.gnss_systems import DEFAULT_MAX_AGE_S, KEPLER_SYSTEMS, STATE_SYSTEMS
from processing.units import NS_PER_S

GM_GPS_M3_S2 = 3.986005e14
"""WGS 84 value of GM used by the GPS user algorithm (IS-GPS-200, 20.3.3.4.3)."""
GM_GAL_M3_S2 = 3.986004418e14
"""Galileo OS SIS ICD (GTRF) and BeiDou (CGCS2000) value."""
OMEGA_E_GPS_RAD_S = 7.2921151467e-5
"""Earth rotation rate of IS-GPS-200 (also Galileo, BeiDou: 7.2921150e-5 differs by 1.5e-13 rad/s)."""
OMEGA_E_BDS_RAD_S = 7.2921150e-5
GM_GLO_M3_S2 = 398600.4418e9
"""GLONASS ICD ed. 5.1, PZ-90.11."""
AE_GLO_M = 6378136.0
J2_GLO = 1082625.75e-9
OMEGA_E_GLO_RAD_S = 7.2921151467e-5
GLONASS_STEP_S = 30.0
KEPLER_ITERATIONS = 10


class EphemerisError(ValueError):
    """Navigation columns missing or of the wrong shape."""


def _col(nav: Mapping[str, Any], name: str) -> NDArray[Any]:
    try:
        return np.asarray(nav[name])
    except KeyError:
        raise EphemerisError(f"navigation data lack the column {name!r} (expected the rinex_nav columns)") from None


def kepler_positions_E(nav: Mapping[str, Any], index: ArrayLike, tai_ns: ArrayLike) -> NDArray[np.float64]:
    """Earth-fixed positions (m) from Keplerian broadcast records (IS-GPS-200 table 20-IV).

    nav: rinex_nav columns; index: (...) int, record row for each evaluation; tai_ns: (...) int64,
    broadcast with index. Returns (..., 3) m in the ECEF frame of the system at those instants.
    """
    idx, t = np.broadcast_arrays(np.asarray(index, dtype=np.int64), np.asarray(tai_ns, dtype=np.int64))
    system = _col(nav, "system")[idx].astype(str)
    g = {name: _col(nav, name)[idx].astype(np.float64) for name in (
        "sqrt_a_sqrt_m", "delta_n_rad_s", "m0_rad", "e", "omega_rad", "cus_rad", "cuc_rad", "crs_m", "crc_m",
        "cis_rad", "cic_rad", "i0_rad", "idot_rad_s", "omega0_rad", "omega_dot_rad_s", "toe_s")}
    tk = (t - _col(nav, "ref_tai_ns")[idx].astype(np.int64)).astype(np.float64) / NS_PER_S
    gm = np.where(system == "G", GM_GPS_M3_S2, np.where(system == "J", GM_GPS_M3_S2, GM_GAL_M3_S2))
    omega_e = np.where(system == "C", OMEGA_E_BDS_RAD_S, OMEGA_E_GPS_RAD_S)
    a = g["sqrt_a_sqrt_m"] ** 2
    n = np.sqrt(gm / a**3) + g["delta_n_rad_s"]
    m = g["m0_rad"] + n * tk
    e = g["e"]
    ecc = m.copy()
    for _ in range(KEPLER_ITERATIONS):  # Newton on E - e sin E = M; e < 0.03 converges in 3-4 steps
        ecc = ecc - (ecc - e * np.sin(ecc) - m) / (1.0 - e * np.cos(ecc))
    nu = np.arctan2(np.sqrt(1.0 - e * e) * np.sin(ecc), np.cos(ecc) - e)
    phi = nu + g["omega_rad"]
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    u = phi + g["cus_rad"] * s2 + g["cuc_rad"] * c2
    r = a * (1.0 - e * np.cos(ecc)) + g["crs_m"] * s2 + g["crc_m"] * c2
    inc = g["i0_rad"] + g["cis_rad"] * s2 + g["cic_rad"] * c2 + g["idot_rad_s"] * tk
    xp, yp = r * np.cos(u), r * np.sin(u)
    geo = (system == "C") & np.isin(_col(nav, "prn")[idx], [1, 2, 3, 4, 5, 59, 60, 61, 62, 63])
    node = np.where(
        geo,
        g["omega0_rad"] + g["omega_dot_rad_s"] * tk - omega_e * g["toe_s"],
        g["omega0_rad"] + (g["omega_dot_rad_s"] - omega_e) * tk - omega_e * g["toe_s"],
    )
    cn, sn, ci, si = np.cos(node), np.sin(node), np.cos(inc), np.sin(inc)
    x = xp * cn - yp * ci * sn
    y = xp * sn + yp * ci * cn
    z = yp * si
    if np.any(geo):  # BeiDou GEO: R_Z(omega_e tk) R_X(-5 deg) applied to the inertial-like (x, y, z)
        c5, s5 = np.cos(np.deg2rad(-5.0)), np.sin(np.deg2rad(-5.0))
        y5, z5 = c5 * y + s5 * z, -s5 * y + c5 * z
        ang = omega_e * tk
        ca, sa = np.cos(ang), np.sin(ang)
        xg, yg = ca * x + sa * y5, -sa * x + ca * y5
        x, y, z = np.where(geo, xg, x), np.where(geo, yg, y), np.where(geo, z5, z)
    return np.stack([x, y, z], axis=-1)


def _glonass_rhs(state: NDArray[np.float64], acc: NDArray[np.float64]) -> NDArray[np.float64]:
    """GLONASS ICD A.3.1.2 right-hand side in the rotating PZ-90 frame; state (..., 6) m, m/s."""
    x, y, z, vx, vy, vz = np.moveaxis(state, -1, 0)
    r2 = x * x + y * y + z * z
    r = np.sqrt(r2)
    mu_r3 = GM_GLO_M3_S2 / (r2 * r)
    j = 1.5 * J2_GLO * GM_GLO_M3_S2 * AE_GLO_M**2 / (r2 * r2 * r)
    zz = 5.0 * z * z / r2
    w2 = OMEGA_E_GLO_RAD_S**2
    ax = -mu_r3 * x - j * x * (1.0 - zz) + w2 * x + 2.0 * OMEGA_E_GLO_RAD_S * vy + acc[..., 0]
    ay = -mu_r3 * y - j * y * (1.0 - zz) + w2 * y - 2.0 * OMEGA_E_GLO_RAD_S * vx + acc[..., 1]
    az = -mu_r3 * z - j * z * (3.0 - zz) + acc[..., 2]
    return np.stack([vx, vy, vz, ax, ay, az], axis=-1)


def glonass_integrate(state0: ArrayLike, acc: ArrayLike, dt_s: ArrayLike, step_s: float = GLONASS_STEP_S
                      ) -> NDArray[np.float64]:
    """Integrate GLONASS broadcast states (GLONASS ICD ed. 5.1, A.3.1.2) by RK4 and interpolate.

    state0: (R, 6) state at tb (m, m/s, PZ-90); acc: (R, 3) luni-solar accelerations (m/s^2), held
    constant; dt_s: (R, K) offsets from tb (s, either sign). Every record is integrated on the common
    grid 0, +-step, +-2 step, ... up to max |dt|, all records at once, and the states at dt are cubic
    Hermite interpolations between grid nodes. Returns (R, K, 6).
    """
    s0 = np.asarray(state0, dtype=np.float64)
    a = np.asarray(acc, dtype=np.float64)
    dt = np.asarray(dt_s, dtype=np.float64)
    if s0.ndim != 2 or s0.shape[1] != 6 or a.shape != (s0.shape[0], 3) or dt.ndim != 2 or dt.shape[0] != s0.shape[0]:
        raise EphemerisError(f"expected state0 (R, 6), acc (R, 3), dt_s (R, K); got {s0.shape}, {a.shape}, {dt.shape}")
    out = np.full(dt.shape + (6,), np.nan)
    if dt.size == 0 or s0.shape[0] == 0:
        return out
    finite = np.isfinite(dt)
    span = float(np.max(np.abs(np.where(finite, dt, 0.0)))) if np.any(finite) else 0.0
    k = int(np.ceil(span / step_s)) + 1
    for sign in (1.0, -1.0):
        h = sign * step_s
        nodes = [s0]
        s = s0
        for _ in range(k):
            k1 = _glonass_rhs(s, a)
            k2 = _glonass_rhs(s + 0.5 * h * k1, a)
            k3 = _glonass_rhs(s + 0.5 * h * k2, a)
            k4 = _glonass_rhs(s + h * k3, a)
            s = s + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            nodes.append(s)
        grid = np.stack(nodes, axis=1)  # (R, k + 1, 6)
        side = finite & ((dt >= 0) if sign > 0 else (dt < 0))
        pos = np.where(side, np.abs(dt), 0.0) / step_s
        j = np.minimum(np.floor(pos).astype(np.int64), k - 1)
        tau = pos - j
        rows = np.arange(s0.shape[0])[:, None]
        p0, p1 = grid[rows, j], grid[rows, j + 1]
        # Cubic Hermite on position with velocities (times step h, signed), linear-consistent on velocity.
        t_ = tau[..., None]
        h00 = 2 * t_**3 - 3 * t_**2 + 1
        h10 = t_**3 - 2 * t_**2 + t_
        h01 = -2 * t_**3 + 3 * t_**2
        h11 = t_**3 - t_**2
        pos_i = h00 * p0[..., :3] + h10 * h * p0[..., 3:] + h01 * p1[..., :3] + h11 * h * p1[..., 3:]
        # Velocity: derivative of the Hermite cubic.
        d00 = (6 * t_**2 - 6 * t_) / h
        d10 = 3 * t_**2 - 4 * t_ + 1
        d01 = (-6 * t_**2 + 6 * t_) / h
        d11 = 3 * t_**2 - 2 * t_
        vel_i = d00 * p0[..., :3] + d10 * p0[..., 3:] + d01 * p1[..., :3] + d11 * p1[..., 3:]
        out = np.where(side[..., None], np.concatenate([pos_i, vel_i], axis=-1), out)
    return out


@dataclass(frozen=True)
class SatellitePositions:
    """Navigation-satellite positions on a time grid.

    sats: (S,) names ("G05", "R12"); r_E: (T, S, 3) m, NaN where no usable record; valid: (T, S);
    age_s: (T, S) t - t_ref of the record used (NaN where none).
    """

    sats: NDArray[np.object_]
    r_E: NDArray[np.float64]
    valid: NDArray[np.bool_]
    age_s: NDArray[np.float64]


def record_jumps_m(nav: Mapping[str, Any]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Consistency of consecutive records of each satellite: distance (m) between the position of a
    record and of its predecessor (resp. successor) evaluated at the record's own reference time.

    Returns (to_previous_m, to_next_m), each (R,), NaN where the satellite has no such neighbour.
    Consecutive GPS records agree to about a metre (IS-GPS-200 user range error), GLONASS ones over
    30 min to a few metres; a record far from both neighbours is corrupt (brdc2800.15n has one for G10).
    """
    sat = _col(nav, "sat").astype(str)
    ref = _col(nav, "ref_tai_ns").astype(np.int64)
    order = np.lexsort((ref, sat))
    prev = np.full(sat.size, np.nan)
    nxt = np.full(sat.size, np.nan)
    pairs_a, pairs_b = [], []
    for a, b in zip(order[:-1], order[1:], strict=True):
        if sat[a] == sat[b]:
            pairs_a.append(a)
            pairs_b.append(b)
    if not pairs_a:
        return prev, nxt
    pa, pb = np.array(pairs_a), np.array(pairs_b)
    system = np.array([s[0] for s in sat[pa]])
    d = np.full(pa.size, np.nan)
    kep = np.isin(system, KEPLER_SYSTEMS)
    if np.any(kep):
        d[kep] = np.linalg.norm(kepler_positions_E(nav, pa[kep], ref[pb[kep]])
                                - kepler_positions_E(nav, pb[kep], ref[pb[kep]]), axis=-1)
    st = np.isin(system, STATE_SYSTEMS)
    if np.any(st):
        cols = ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")
        s0 = np.stack([_col(nav, c)[pa[st]].astype(float) for c in cols], axis=-1)
        acc = np.nan_to_num(np.stack([_col(nav, c)[pa[st]].astype(float) for c in ("ax_m_s2", "ay_m_s2", "az_m_s2")],
                                     axis=-1))
        dt = ((ref[pb[st]] - ref[pa[st]]) / NS_PER_S)[:, None]
        r1 = glonass_integrate(s0, acc, dt)[:, 0, :3]
        d[st] = np.linalg.norm(r1 - np.stack([_col(nav, c)[pb[st]].astype(float)
                                              for c in cols[:3]], axis=-1), axis=-1)
    nxt[pa] = d
    prev[pb] = d
    return prev, nxt


def inconsistent_records(nav: Mapping[str, Any], tol_m: float = 200.0) -> NDArray[np.bool_]:
    """Records farther than tol_m from every neighbour that exists (see :func:`record_jumps_m`); (R,) bool."""
    prev, nxt = record_jumps_m(nav)
    far_prev = ~(prev <= tol_m)
    far_next = ~(nxt <= tol_m)
    has = np.isfinite(prev) | np.isfinite(nxt)
    return has & far_prev & far_next


def select_records(nav: Mapping[str, Any], sats: Sequence[str], tai_ns: ArrayLike,
                   max_age_s: Mapping[str, float] | None = None, healthy_only: bool = True,
                   usable: ArrayLike | None = None) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """For each time and satellite, the record with the nearest reference time within max age.

    usable: optional (R,) bool mask of records allowed (e.g. ~inconsistent_records(nav)).
    Returns (index (T, S) int64, -1 where none; age_s (T, S) = t - t_ref, NaN where none).
    """
    t = np.atleast_1d(np.asarray(tai_ns, dtype=np.int64))
    limits = {**DEFAULT_MAX_AGE_S, **(max_age_s or {})}
    sat_col = _col(nav, "sat").astype(str)
    ref = _col(nav, "ref_tai_ns").astype(np.int64)
    health = _col(nav, "health").astype(np.float64)
    allowed = np.ones(sat_col.size, bool) if usable is None else np.asarray(usable, dtype=bool)
    index = np.full((t.size, len(sats)), -1, dtype=np.int64)
    age = np.full((t.size, len(sats)), np.nan)
    for j, sat in enumerate(sats):
        rows = np.flatnonzero((sat_col == sat) & ((health == 0) | ~healthy_only) & allowed)
        if rows.size == 0:
            continue
        rows = rows[np.argsort(ref[rows], kind="stable")]
        refs = ref[rows]
        k = np.clip(np.searchsorted(refs, t), 1, max(1, refs.size - 1)) if refs.size > 1 else np.zeros(t.size, int)
        if refs.size > 1:
            left, right = k - 1, k
            pick = np.where(np.abs(t - refs[left]) <= np.abs(refs[right] - t), left, right)
        else:
            pick = k
        d = (t - refs[pick]).astype(np.float64) / NS_PER_S
        ok = np.abs(d) <= limits.get(sat[0], 7200.0)
        index[:, j] = np.where(ok, rows[pick], -1)
        age[:, j] = np.where(ok, d, np.nan)
    return index, age


def satellite_positions_E(nav: Mapping[str, Any], tai_ns: ArrayLike, sats: Sequence[str] | None = None, *,
                          max_age_s: Mapping[str, float] | None = None, healthy_only: bool = True,
                          reject_inconsistent: bool = True) -> SatellitePositions:
    """Positions (ITRF, m) of navigation satellites at the given instants from broadcast records.

    nav: rinex_nav columns (:mod:`processing.formats.rinex_nav`); tai_ns: (T,) int64; sats: names to
    evaluate (default: every satellite of a supported system in nav). Keplerian systems by
    :func:`kepler_positions_E`, GLONASS/SBAS by :func:`glonass_integrate`. Where a satellite has no
    healthy record within ``max_age_s`` (per system letter, :data:`DEFAULT_MAX_AGE_S`) the row is NaN
    and ``valid`` False. reject_inconsistent: skip records that disagree with both neighbours
    (:func:`inconsistent_records`).
    """
    t = np.atleast_1d(np.asarray(tai_ns, dtype=np.int64))
    sat_col = _col(nav, "sat").astype(str)
    supported = set(KEPLER_SYSTEMS) | set(STATE_SYSTEMS)
    names = sorted({s for s in sat_col if s[0] in supported}) if sats is None else [str(s) for s in sats]
    usable = ~inconsistent_records(nav) if reject_inconsistent else None
    index, age = select_records(nav, names, t, max_age_s, healthy_only, usable)
    r = np.full(index.shape + (3,), np.nan)
    system_of = np.array([s[0] for s in names]) if names else np.zeros(0, str)
    kep = (index >= 0) & np.isin(system_of, KEPLER_SYSTEMS)[None, :]
    if np.any(kep):
        tt = np.broadcast_to(t[:, None], index.shape)
        r[kep] = kepler_positions_E(nav, index[kep], tt[kep])
    state = (index >= 0) & np.isin(system_of, STATE_SYSTEMS)[None, :]
    if np.any(state):
        used = np.unique(index[state])
        s0 = np.stack([_col(nav, c)[used].astype(float) for c in ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")],
                      axis=-1)
        acc = np.nan_to_num(np.stack([_col(nav, c)[used].astype(float) for c in ("ax_m_s2", "ay_m_s2", "az_m_s2")],
                                     axis=-1))
        # Offsets per used record: every (time, sat) cell assigned to it, padded with NaN.
        cell_t, cell_s = np.nonzero(state)
        rec = np.searchsorted(used, index[cell_t, cell_s])
        counts = np.bincount(rec, minlength=used.size)
        width = int(counts.max())
        order = np.argsort(rec, kind="stable")
        slot = np.arange(order.size) - np.repeat(np.cumsum(counts) - counts, counts)
        dt = np.full((used.size, width), np.nan)
        dt[rec[order], slot] = age[cell_t[order], cell_s[order]]
        states = glonass_integrate(s0, acc, dt)
        r[cell_t[order], cell_s[order]] = states[rec[order], slot, :3]
    valid = np.isfinite(r).all(axis=-1)
    return SatellitePositions(sats=np.array(names, dtype=object), r_E=r, valid=valid,
                              age_s=np.where(valid, age, np.nan))
