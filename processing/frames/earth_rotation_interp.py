"""Fast GCRS -> ITRS rotation for long, densely sampled series (1 Hz telemetry over hours or days).

Same model as :func:`processing.frames.earth_orientation.gcrs_to_itrs_mat` (IAU 2006/2000A, CIO based, ERFA), composed
as ERFA's c2t06a does, dcm_EI = RPOM R3(ERA) RC2I, but the celestial-to-intermediate matrix RC2I
(precession-nutation, the expensive part: ~70 us per date in erfa.c2i06a) is evaluated on nodes every
``node_step_s`` of TT and interpolated linearly per element; the Earth rotation angle (ERA) and polar
motion (RPOM) are evaluated at every sample. RC2I moves by at most ~1.5e-9 rad/min of nutation (the
fortnightly terms) so linear interpolation over 1 h errs by < 1e-11 rad (tested against
frames.gcrs_to_itrs_mat to 1e-10 rad; ~60 ns of time at the Earth's rotation rate, 0.5 mm at 7000 km).

This belongs beside processing.frames.earth_orientation; it is a separate module only because that file has another
owner at the moment.
"""

from __future__ import annotations

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.frames.earth_orientation import EarthOrientation
from processing.time.julian_dates import tai_ns_to_ut1_jd
from processing.time.timescales import TT_MINUS_TAI_NS, UNIX_EPOCH_JD
from processing.units import NS_PER_DAY, OMEGA_EARTH_RAD_S

__all__ = ["gcrs_to_itrs_mat_interp", "itrs_to_gcrs_state_interp"]


def _jd(ns: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
    day = ns // NS_PER_DAY
    return UNIX_EPOCH_JD + day.astype(np.float64), (ns - day * NS_PER_DAY) / NS_PER_DAY


def gcrs_to_itrs_mat_interp(
    tai_ns: ArrayLike, eop: EarthOrientation | None = None, *, node_step_s: int = 3600
) -> NDArray:
    """dcm_EI (..., 3, 3) (r_E = dcm_EI @ r_I) like frames.gcrs_to_itrs_mat, with RC2I interpolated.

    tai_ns: (...) int64; eop: Earth orientation (default zero); node_step_s: spacing of the RC2I nodes.
    """
    return _dcm_and_rpom(tai_ns, eop, node_step_s)[0]


def _dcm_and_rpom(tai_ns: ArrayLike, eop: EarthOrientation | None, node_step_s: int) -> tuple[NDArray, NDArray]:
    eop = EarthOrientation() if eop is None else eop
    t = np.asarray(tai_ns)
    if t.dtype.kind not in "iu":
        raise ValueError(f"tai_ns must be integer nanoseconds (int64), got dtype {t.dtype}")
    flat = np.ravel(t).astype(np.int64) + TT_MINUS_TAI_NS
    if flat.size == 0:
        return np.zeros(t.shape + (3, 3)), np.zeros(t.shape + (3, 3))
    step = int(node_step_s) * 1_000_000_000
    k = flat // step
    nodes = np.arange(k.min(), k.max() + 2, dtype=np.int64)
    rc2i_nodes = np.asarray(erfa.c2i06a(*_jd(nodes * step)))
    i = k - nodes[0]
    f = ((flat - k * step) / step)[:, None, None]
    rc2i = (1.0 - f) * rc2i_nodes[i] + f * rc2i_nodes[i + 1]
    tt1, tt2 = _jd(flat)
    ut1, ut2 = tai_ns_to_ut1_jd(np.ravel(t), dut1_s=np.ravel(np.broadcast_to(eop.dut1_s, t.shape)))
    era = erfa.era00(ut1, ut2)
    xp = np.ravel(np.broadcast_to(eop.xp_rad, t.shape))
    yp = np.ravel(np.broadcast_to(eop.yp_rad, t.shape))
    rpom = erfa.pom00(xp, yp, erfa.sp00(tt1, tt2))
    out = np.asarray(erfa.c2tcio(rc2i, era, rpom))
    return out.reshape(t.shape + (3, 3)), np.asarray(rpom).reshape(t.shape + (3, 3))


def itrs_to_gcrs_state_interp(
    r_E: ArrayLike, v_E: ArrayLike, tai_ns: ArrayLike, eop: EarthOrientation | None = None
) -> tuple[NDArray, NDArray, NDArray]:
    """GCRS state from an ITRS one (velocity relative to the Earth), and dcm_EI, with the fast matrix.

    r_E, v_E: (N, 3) m, m/s; tai_ns (N,). Returns r_I, v_I (N, 3) and dcm_EI (N, 3, 3):
    r_I = R^T r_E, v_I = R^T (v_E + w x r_E) with w = OMEGA_EARTH_RAD_S along the ITRS z axis (the CIP
    direction differs by the polar motion, < 1e-6 rad: < 1e-2 mm/s at LEO radius).
    """
    r = np.asarray(r_E, dtype=np.float64)
    v = np.asarray(v_E, dtype=np.float64)
    dcm_EI, rpom = _dcm_and_rpom(tai_ns, eop, 3600)
    omega = OMEGA_EARTH_RAD_S * rpom[..., :, 2]
    r_I = np.einsum("...ji,...j->...i", dcm_EI, r)
    v_I = np.einsum("...ji,...j->...i", dcm_EI, v + np.cross(omega, r))
    return r_I, v_I, dcm_EI
