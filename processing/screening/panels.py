"""Screening of the solar-panel currents (002 eq. 17): range, Earth shadow and, without an attitude, the
unit norm of the sun vector the lit panels determine (:func:`sun_from_currents`, also the sun vector of
processing.vector_attitude).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp
from processing.screening.base import Collector, Columns, Environment, ScreeningParams, generic_checks, sensor_groups
from processing.screening.gnss import GnssTrack
from processing.spacecraft import Spacecraft


def pivot(times: NDArray[np.int64], keys: NDArray[Any]) -> tuple[NDArray[np.int64], NDArray[Any], NDArray[np.int64]]:
    """Long rows (time, key) -> epochs (T,), keys (K,), and index (T, K) of the row (-1 where none)."""
    ut, ti = np.unique(times, return_inverse=True)
    uk, ki = np.unique(keys, return_inverse=True)
    index = np.full((ut.size, uk.size), -1, dtype=np.int64)
    index[ti, ki] = np.arange(times.size)
    return ut, uk, index


def sun_from_currents(currents_a: ArrayLike, normals_B: ArrayLike, max_current_a: ArrayLike,
                      lit_threshold_a: float = 0.0, iterations: int = 5
                      ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Sun vector in the body frame from panel currents, I_i = I_max,i max(0, n_i . s) (002, eq. 17 model).

    currents_a: (T, P) (NaN: missing); normals_B: (P, 3); max_current_a: (P,). Gauss-Newton on the
    panels whose model is lit (n . s > 0), started from the least-squares solution of all panels
    (for opposite panel pairs that start is already along the sun). Returns (s_B (T, 3) not
    normalised: |s| = 1 for consistent currents; determined (T,): the normals of the panels that
    constrain s -- lit ones, and dark ones within lit_threshold of their terminator, n . s > -threshold
    / I_max, which pin the component along them to about zero -- span three dimensions).
    """
    cur = np.asarray(currents_a, dtype=np.float64)
    n = np.asarray(normals_B, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    imax = np.asarray(max_current_a, dtype=np.float64)
    y = cur / imax
    have = np.isfinite(y)
    y0 = np.where(have, y, 0.0)
    w = have.astype(float)
    a = np.einsum("tp,pi,pj->tij", w, n, n) + 1e-9 * np.eye(3)
    s = np.linalg.solve(a, np.einsum("tp,pi->ti", w * y0, n)[..., None])[..., 0]
    margin = lit_threshold_a / np.maximum(imax, 1e-12)
    for _ in range(iterations):
        wa = (have & (np.einsum("pi,ti->tp", n, s) > 0)).astype(float)
        a = np.einsum("tp,pi,pj->tij", wa, n, n) + 1e-9 * np.eye(3)
        s = np.linalg.solve(a, np.einsum("tp,pi->ti", wa * y0, n)[..., None])[..., 0]
    constraining = have & (np.einsum("pi,ti->tp", n, s) > -margin)
    span = np.einsum("tp,pi,pj->tij", constraining.astype(float), n, n)
    determined = np.linalg.eigvalsh(span)[:, 0] > 1e-3
    return s, determined


def screen_panels(col: Collector, cols: Columns, spacecraft: Spacecraft, p: ScreeningParams,
                  track: GnssTrack | None, env: Environment, notes: list[str],
                  findings: dict[str, Any] | None = None) -> None:
    """panel_range, panel_eclipse and panel_sun_norm (002 eq. 17) where the solar panels are configured
    (the ``panel`` column indexes ``spacecraft.solar_panels``), and the generic checks per panel."""
    panel_cfg = (spacecraft.panel_normals_B(), spacecraft.panel_max_current_a()) if spacecraft.solar_panels else None
    d_i = p.current_error_a + p.current_model_error_a
    tol = p.k_current * d_i
    for _sensor, rows in sensor_groups(cols):
        t_all = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        panel = np.asarray(cols["panel"], dtype=np.int64)[rows]
        cur = np.asarray(cols["current_a"], dtype=np.float64)[rows]
        for k in np.unique(panel):
            sub = rows[panel == k]
            generic_checks(col, cols, "panel_currents", sub, p, findings=findings,
                           stuck_ignore=np.abs(np.asarray(cols["current_a"], dtype=float)[sub]) <= tol)
        if panel_cfg is None:
            continue
        normals, imax = panel_cfg
        known = (panel >= 0) & (panel < imax.size)
        if not np.all(known):
            notes.append(f"{int(np.sum(~known))} panel_currents rows name panels not in the configuration")
        im = np.where(known, imax[np.clip(panel, 0, imax.size - 1)], np.nan)
        stat = np.where(cur < 0, -cur, np.maximum(cur - im, 0.0))
        col.add("panel_range", rows, (cur < -tol) | (cur > im + tol), stat, tol, "A", "002 eq. 17", known)
        if track is None:
            continue
        epochs, keys, index = pivot(t_all, panel)
        r_E, _ = track.at(epochs, p.max_interpolation_gap_s)
        ok = np.isfinite(r_E).all(axis=1)
        nu = np.full(epochs.size, np.nan)
        if np.any(ok):
            r_I = np.einsum("nji,nj->ni", gcrs_to_itrs_mat_interp(epochs[ok]), r_E[ok])
            nu[ok] = env.sunlit_fraction(r_I, env.sun_position_I_m(epochs[ok]))
        row_nu = np.full(rows.size, np.nan)
        ti = np.searchsorted(epochs, t_all)
        row_nu = nu[ti]
        applied = np.isfinite(row_nu) & known & (row_nu < 1.0)
        excess = cur - row_nu * np.nan_to_num(im)
        col.add("panel_eclipse", rows, applied & (excess > tol), np.where(applied, excess, np.nan), tol, "A",
                "002 eq. 17", applied)
        if not p.sun_norm:
            continue
        # Attitude-free form of eq. 17: in full sunlight the currents must give a unit sun vector.
        valid_keys = (keys >= 0) & (keys < imax.size)
        kk = keys[valid_keys]
        mat = np.full((epochs.size, kk.size), np.nan)
        idx = index[:, valid_keys]
        mat[idx >= 0] = cur[idx[idx >= 0]]
        pre = col.items.get("spike", {}).get("flagged")
        if pre is not None:
            # samples already rejected as spikes do not vote
            rej = np.zeros(mat.shape, bool)
            rej[idx >= 0] = pre[rows[idx[idx >= 0]]]
            mat = np.where(rej, np.nan, mat)
        s, determined = sun_from_currents(mat, normals[kk], imax[kk], lit_threshold_a=tol)
        complete = np.isfinite(mat).all(axis=1) & (kk.size == imax.size)  # a missing panel biases |s|
        sunlit = (nu >= 1.0) & complete
        lit = np.isfinite(mat) & (mat > tol)
        n_lit = lit.sum(axis=1)
        norm_dev = np.abs(np.linalg.norm(s, axis=1) - 1.0)
        tol_norm = p.k_current * d_i * np.sqrt(np.maximum(n_lit, 1)) / float(np.min(imax[kk]))
        bad_epoch = sunlit & determined & (norm_dev > tol_norm)
        applied_epoch = sunlit & determined
        row_flag = np.zeros(rows.size, bool)
        row_applied = np.zeros(rows.size, bool)
        row_stat = np.full(rows.size, np.nan)
        sel = idx >= 0
        ep = np.nonzero(sel)[0]
        rr = idx[sel]
        row_flag[rr] = bad_epoch[ep] & lit[sel]
        row_applied[rr] = applied_epoch[ep]
        row_stat[rr] = norm_dev[ep]
        th_norm = float(np.median(tol_norm[applied_epoch])) if np.any(applied_epoch) else float("nan")
        col.add("panel_sun_norm", rows, row_flag, row_stat, th_norm, "", "002 eq. 17", row_applied)
    if track is None:
        notes.append("no accepted GNSS samples: panel_eclipse and panel_sun_norm (eq. 17) not applied")
