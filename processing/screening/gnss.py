"""Screening of the GNSS stream (002 eq. 15 and the generic orbit checks of processing.screening.criteria):
energy integral, orbit plane, kinematic and velocity consistency. Its accepted samples become the
position model (:class:`GnssTrack`) of the other streams' criteria.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp
from processing.screening.base import Collector, Columns, ScreeningParams, sensor_groups
from processing.screening.tools import (
    attribute_increments,
    energy_h,
    energy_tolerance,
    hermite_state,
    inertial_velocity_E,
    jerk_bound_m_s3,
    local_velocity_fit,
    robust_polyfit,
    rolling_median,
    stuck,
    time_grid_irregular,
)
from processing.units import J2_EARTH, MU_EARTH_M3_S2, NS_PER_S, OMEGA_EARTH_RAD_S, R_EARTH_M


@dataclass(frozen=True)
class GnssTrack:
    """Accepted GNSS states used as the position model of the other criteria (ITRF)."""

    time_tai_ns: NDArray[np.int64]
    r_E: NDArray[np.float64]
    v_E: NDArray[np.float64]

    def at(self, t_ns: ArrayLike, max_gap_s: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return hermite_state(self.time_tai_ns, self.r_E, self.v_E, t_ns, max_gap_s)


def reference_h(reference: Columns, frame: str, t_ns: NDArray[np.int64], model: str) -> NDArray[np.float64]:
    from scipy.interpolate import CubicSpline

    tr = np.asarray(reference["time_tai_ns"], dtype=np.int64)
    r = np.stack([np.asarray(reference[c], dtype=np.float64) for c in ("x", "y", "z")], axis=1)
    v = np.stack([np.asarray(reference[c], dtype=np.float64) for c in ("vx", "vy", "vz")], axis=1)
    order = np.argsort(tr)
    tr, r, v = tr[order], r[order], v[order]
    if frame.upper() not in ("ITRF", "ITRS", "E"):  # inertial reference: to ITRF for the J2_EARTH latitude
        m = gcrs_to_itrs_mat_interp(tr)
        r_e = np.einsum("nij,nj->ni", m, r)
        v_e = np.einsum("nij,nj->ni", m, v) - np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r_e)
        r, v = r_e, v_e
    h = energy_h(r, v, model)
    out = np.full(t_ns.size, np.nan)
    if tr.size < 4:
        return out
    x = (tr - tr[0]) / NS_PER_S
    spline = CubicSpline(x, h)
    xq = (t_ns - tr[0]) / NS_PER_S
    inside = (xq >= x[0]) & (xq <= x[-1])
    out[inside] = spline(xq[inside])
    return out


def screen_time_tags(col: Collector, t: NDArray[np.int64], r: NDArray[np.float64], v: NDArray[np.float64],
                     rows: NDArray[np.int64], p: ScreeningParams, findings: dict[str, Any] | None) -> NDArray[np.bool_]:
    """The ``time_tag`` criterion (processing.orbits.gnss_checks.time_tag_check): states whose position and
    velocity residuals against a robust local orbit are both those of a time shift tau, |tau| beyond
    k_time_tag x dr / |v|. Returns the flagged rows (n,) and adds the estimated offsets to ``findings``."""
    from processing.orbits.gnss_checks import time_tag_check

    dr, dv = p.gnss_position_error_m, p.gnss_velocity_error_m_s
    chk = time_tag_check(t, r, v, position_sigma_m=dr, velocity_sigma_m_s=dv, k=p.k_time_tag)
    speed = np.linalg.norm(v, axis=1)
    tol = p.k_time_tag * dr / np.maximum(speed, 1.0)
    stat = np.abs(chk.offset_s)
    flagged = chk.applied & chk.shift_consistent & (stat > tol)
    col.add("time_tag", rows, flagged, np.where(chk.applied, chk.offset_s, np.nan), float(np.median(tol)), "s",
            "generic", chk.applied)
    if findings is not None and np.any(flagged):
        tau = chk.offset_s[flagged]
        runs = int(np.sum(np.diff(np.concatenate([[0], flagged.astype(np.int8), [0]])) == 1))
        findings.setdefault("gnss_time_tags", []).append({
            "n_states": int(flagged.sum()), "n_runs": runs, "offset_s_median": float(np.median(tau)),
            "offset_s_min": float(np.min(tau)), "offset_s_max": float(np.max(tau)),
            "first_tai_ns": int(t[flagged][0]), "last_tai_ns": int(t[flagged][-1])})
    return flagged


def screen_orbit_plane(col: Collector, t: NDArray[np.int64], r: NDArray[np.float64], v: NDArray[np.float64],
                       dt: NDArray[np.float64], rows: NDArray[np.int64], p: ScreeningParams,
                       bad: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The ``orbit_plane`` criterion of :func:`screen_gnss`: the orbit normal's angle to its rolling median
    (samples already ``bad`` excluded) beyond k_plane x its noise plus the J2 wobble. Returns the flagged rows."""
    dr, dv = p.gnss_position_error_m, p.gnss_velocity_error_m_s
    vi = inertial_velocity_E(r, v)
    nrm = np.cross(r, vi)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    # Undo the Earth's rotation (about z, from the first sample) so that the normal is nearly fixed
    # and a one-sided window (next to rejected samples) does not bias the median.
    theta = OMEGA_EARTH_RAD_S * (t - t[0]) / NS_PER_S
    ct, st_ = np.cos(theta), np.sin(theta)
    nrm = np.stack([ct * nrm[:, 0] - st_ * nrm[:, 1], st_ * nrm[:, 0] + ct * nrm[:, 1], nrm[:, 2]], axis=1)
    period_s = float(np.median(dt)) if dt.size else 1.0
    hw = max(2, int(round(p.plane_window_s / max(period_s, 1e-9))))
    med = rolling_median(nrm, hw, exclude=bad)
    med = med / np.linalg.norm(med, axis=1, keepdims=True)
    ang = np.arccos(np.clip(np.sum(nrm * med, axis=1), -1.0, 1.0))
    rn = np.linalg.norm(r, axis=1)
    # noise, plus the J2_EARTH wobble of the normal (rate < 3 J2_EARTH (R/r)^2 n) over half the window, which a
    # one-sided window (next to rejected samples or at the ends) turns into a bias
    wobble = 3.0 * J2_EARTH * (R_EARTH_M / rn) ** 2 * np.sqrt(MU_EARTH_M3_S2 / rn**3) * 0.5 * hw * period_s
    tol_plane = p.k_plane * (dv / np.linalg.norm(vi, axis=1) + dr / rn) + wobble
    applied = np.isfinite(ang)
    col.add("orbit_plane", rows, ang > tol_plane, ang, float(np.nanmedian(tol_plane)), "rad", "generic", applied)
    return applied & (ang > tol_plane)


def screen_gnss(col: Collector, cols: Columns, p: ScreeningParams, reference: Columns | None,
                 reference_frame: str, notes: list[str], findings: dict[str, Any] | None = None) -> GnssTrack | None:
    track = None
    for _sensor, rows_all in sensor_groups(cols):
        t_all = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows_all]
        r_all = np.stack([np.asarray(cols[c], dtype=np.float64)[rows_all] for c in ("x", "y", "z")], axis=1)
        v_all = np.stack([np.asarray(cols[c], dtype=np.float64)[rows_all] for c in ("vx", "vy", "vz")], axis=1)
        late = screen_time_tags(col, t_all, r_all, v_all, rows_all, p, findings) if p.k_time_tag > 0 else \
            np.zeros(rows_all.size, bool)
        # the other criteria judge the states with consistent tags (a late block would make its good
        # neighbours fail the kinematic and velocity tests)
        rows, t, r, v = rows_all[~late], t_all[~late], r_all[~late], v_all[~late]
        dr, dv = p.gnss_position_error_m, p.gnss_velocity_error_m_s
        bad = np.zeros(rows.size, bool)
        # Kinematic consistency of positions (increments vs trapezoid of velocities).
        dt = np.diff(t) / NS_PER_S
        d = np.linalg.norm(r[1:] - r[:-1] - 0.5 * (v[1:] + v[:-1]) * dt[:, None], axis=1)
        jerk = jerk_bound_m_s3(r, v)
        # noise of the increment, plus the trapezoid's truncation error dt^3 / 12 |r'''| (1.7 mm at 1 s)
        tol_inc = (p.k_kinematic * np.sqrt(2 * dr**2 + 0.5 * (dt * dv) ** 2)
                   + dt**3 / 12.0 * np.maximum(jerk[1:], jerk[:-1]))
        kin = attribute_increments(d > tol_inc)
        stat = np.maximum(np.concatenate([[0.0], d]), np.concatenate([d, [0.0]]))
        col.add("kinematic", rows, kin, stat, float(p.k_kinematic * np.sqrt(2 * dr**2 + 0.5 * dv**2)), "m", "generic")
        bad |= kin
        # Energy integral (eq. 15).
        h = energy_h(r, v, p.energy_model)
        model_err = p.energy_model_error_m2_s2
        if model_err is None:
            model_err = 300.0 if p.energy_model == "j2" else 2.5e5
        tol = p.k_energy * (energy_tolerance(r, v, dr, dv) + model_err)
        h_ref = None
        if reference is not None:
            h_ref = reference_h(reference, reference_frame, t, p.energy_model)
            if not np.any(np.isfinite(h_ref)):
                notes.append("the reference orbit does not cover the GNSS samples; energy compared with a robust fit")
                h_ref = None
        if h_ref is None:
            h_ref = robust_polyfit((t - t[0]) / NS_PER_S, h, 1, exclude=bad)
        dev = np.abs(h - h_ref)
        applied = np.isfinite(dev)
        col.add("energy", rows, dev > tol, dev, float(np.nanmedian(tol)), "m^2/s^2", "002 eq. 15", applied)
        bad |= applied & (dev > tol)
        bad |= screen_orbit_plane(col, t, r, v, dt, rows, p, bad)
        # Velocity against the local slope of the positions.
        v_fit, gain, cubic_gain = local_velocity_fit(t, r, p.velocity_half_window, exclude=bad)
        dvv = np.linalg.norm(v - v_fit, axis=1)
        # noise of v and of the slope, plus the slope's bias from the orbit's jerk (0.07 m/s at 1 s)
        tol_v = p.k_velocity * np.sqrt((gain * dr) ** 2 + dv**2) + cubic_gain * jerk / 6.0
        applied = np.isfinite(dvv)
        col.add("velocity", rows, dvv > tol_v, dvv, float(np.nanmedian(tol_v)), "m/s", "generic", applied)
        bad |= applied & (dvv > tol_v)
        flagged_all, dev_t, _, tol_t = time_grid_irregular(t_all, p.time_grid_tolerance)
        col.add("time_grid", rows_all, flagged_all, dev_t, tol_t, "fraction of the sampling period", "generic")
        col.add("stuck", rows, stuck(np.concatenate([r, v], axis=1), p.stuck_min_run), np.full(rows.size, np.nan),
                float(p.stuck_min_run), "samples", "generic")
        bad |= flagged_all[~late]
        if track is None and np.sum(~bad) >= 2:
            track = GnssTrack(t[~bad], r[~bad], v[~bad])
    return track
