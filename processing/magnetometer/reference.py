"""The reference field magnitude |B_ref| along the GNSS orbit (IGRF-14), for |B| matching."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from processing.environment.igrf import igrf_field_E_nT
from processing.units import NS_PER_S

__all__ = ["reference_field_norm_nT"]


def reference_field_norm_nT(mag_time_tai_ns: NDArray[np.int64], gnss_time_tai_ns: NDArray[np.int64],
                            gnss_r_E_m: NDArray[np.float64], gnss_v_E_m_s: NDArray[np.float64], *,
                            max_gnss_gap_s: float = 120.0, field_step_s: float = 10.0,
                            ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """IGRF-14 |B| [nT] at the magnetometer instants, and the mask of the instants it is given for.

    The ITRF position is interpolated by a cubic Hermite on the GNSS position and ITRF velocity
    (processing.gyroless.estimation.hermite_state); instants outside the GNSS span or inside a GNSS gap
    longer than ``max_gnss_gap_s`` are masked out (their |B| is NaN). The magnitude does not depend on
    the frame, so no Earth rotation is needed. Times int64 TAI ns; r (G, 3) m, v (G, 3) m/s.

    The field is synthesised at most every ``field_step_s`` (and at the last sample) and |B| interpolated
    between by a cubic spline (0 or None: at every sample): |B| changes on the half-orbit scale (~3000 s), so
    10 s nodes agree with the synthesis at every sample to the effect of 5 m of GNSS noise (0.08 nT rms against
    the true orbit's field on seed 004, either way) while the synthesis, the costly part, runs 10x less.
    """
    from processing.gyroless.estimation import hermite_state

    t_mag = np.asarray(mag_time_tai_ns, dtype=np.int64)
    t_g = np.asarray(gnss_time_tai_ns, dtype=np.int64)
    ok = (t_mag >= t_g[0]) & (t_mag <= t_g[-1]) if t_g.size >= 2 else np.zeros(t_mag.size, dtype=bool)
    out = np.full(t_mag.size, np.nan)
    if not np.any(ok):
        return out, ok
    i = np.clip(np.searchsorted(t_g, t_mag, side="right") - 1, 0, t_g.size - 2)
    gap_s = (t_g[i + 1] - t_g[i]) / NS_PER_S
    ok &= gap_s <= max_gnss_gap_s
    if not np.any(ok):
        return out, ok
    t_ok = t_mag[ok]
    if field_step_s:
        cell = (t_ok - t_ok[0]) // int(field_step_s * NS_PER_S)
        node = np.concatenate([[True], np.diff(cell) > 0])
        node[-1] = True
    else:
        node = np.ones(t_ok.size, dtype=bool)
    r, _ = hermite_state(t_g, gnss_r_E_m, gnss_v_E_m_s, t_ok[node])
    norm = np.linalg.norm(igrf_field_E_nT(r, t_ok[node]), axis=-1)
    if np.all(node) or np.sum(node) < 4:
        if not np.all(node):
            r, _ = hermite_state(t_g, gnss_r_E_m, gnss_v_E_m_s, t_ok)
            norm = np.linalg.norm(igrf_field_E_nT(r, t_ok), axis=-1)
        out[ok] = norm
        return out, ok
    from scipy.interpolate import CubicSpline

    x = (t_ok[node] - t_ok[0]).astype(np.float64) / NS_PER_S
    out[ok] = CubicSpline(x, norm)((t_ok - t_ok[0]).astype(np.float64) / NS_PER_S)
    return out, ok
