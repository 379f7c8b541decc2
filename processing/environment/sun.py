"""Direction and position of the Sun in the GCRS, from ERFA's Earth ephemeris (epv00).

``sun_position_I_m(tai_ns)`` is the geometric geocentric position of the Sun, GCRS axes (= BCRS/ICRS
axes), minus the heliocentric Earth position of ERFA epv00 (VSOP2000 simplified, IERS/SOFA), time
argument TT used as TDB (|TDB - TT| < 2 ms: < 1e-10 rad).

Accuracy (stated, tested):

- epv00 against JPL DE405 over 1900-2100: heliocentric Earth position 3.7 km rms, 11.2 km max, i.e.
  a geocentric Sun direction error below 11.2 km / 1 au = 7.5e-8 rad (0.016 arcsec), and the
  distance to 11 km.
- ``sun_position_I_m`` evaluates epv00 on nodes every ``NODE_STEP_S`` (1 h) spanning the request and
  interpolates each node pair by a cubic Hermite polynomial with the node velocities: interpolation
  error below 1 cm (tested against direct epv00), since the geocentric Sun moves smoothly (annual
  orbit plus the ~4700 km monthly wobble of the Earth about the Earth-Moon barycentre). This keeps
  the cost ~constant for long 1 Hz series (epv00 itself costs ~30 us per date).
- Not included in the geometric direction: annual aberration (up to 20.5 arcsec; ``apparent=True``
  applies it with ERFA ab for a geocentric observer), the spacecraft's own aberration (< 5.5
  arcsec in LEO), light time (the Sun's barycentric motion over 499 s, < 0.01 arcsec) and the
  parallax of a LEO spacecraft (|r| / 1 au < 5e-5 rad = 10 arcsec; :func:`sun_direction_from_I`
  removes it). All are far below a sun sensor's error (~0.1-1 deg).
- tested against the apparent place of Meeus, Astronomical Algorithms (2nd ed.), example 25.b
  (VSOP87) to < 0.1 arcsec, and at the 2024 March equinox (apparent longitude 0) to < 3 arcsec.
"""

from __future__ import annotations

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.time.timescales import TT_MINUS_TAI_NS, UNIX_EPOCH_JD
from processing.units import AU_M, NS_PER_DAY

__all__ = [
    "AU_M",
    "NODE_STEP_S",
    "SUN_RADIUS_M",
    "sun_direction_I",
    "sun_direction_from_I",
    "sun_position_I_m",
]

SUN_RADIUS_M = 695_700_000.0
"""Nominal solar radius [m] (IAU 2015 Resolution B3)."""
NODE_STEP_S = 3600
"""Spacing of the epv00 evaluation nodes [s] of :func:`sun_position_I_m`."""
_NODE_NS = NODE_STEP_S * 1_000_000_000
_DAY_S = 86400.0


def _tt_jd(tt_ns: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    day = tt_ns // NS_PER_DAY
    return UNIX_EPOCH_JD + day.astype(np.float64), (tt_ns - day * NS_PER_DAY) / NS_PER_DAY


def _as_tai(tai_ns: ArrayLike) -> NDArray[np.int64]:
    t = np.asarray(tai_ns)
    if t.dtype.kind not in "iu":
        raise ValueError(f"tai_ns must be integer nanoseconds (int64), got dtype {t.dtype}")
    return t.astype(np.int64, copy=False)


def _sun_pv_direct(tt_ns: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
    """Geocentric Sun position [m] and velocity [m/s] at TT instants, straight from epv00."""
    jd1, jd2 = _tt_jd(tt_ns)
    pvh, _ = erfa.epv00(jd1, jd2)
    return -pvh["p"] * AU_M, -pvh["v"] * (AU_M / _DAY_S)


def sun_position_I_m(tai_ns: ArrayLike) -> NDArray[np.float64]:
    """Geometric geocentric position of the Sun in the GCRS [m], shape (..., 3) for tai_ns (...).

    See the module docstring for the model and its accuracy (direction < 1e-7 rad, 1900-2100).
    """
    t = _as_tai(tai_ns)
    flat = np.ravel(t) + TT_MINUS_TAI_NS
    if flat.size == 0:
        return np.zeros(t.shape + (3,))
    k = flat // _NODE_NS
    nodes = np.arange(k.min(), k.max() + 2, dtype=np.int64)
    p, v = _sun_pv_direct(nodes * _NODE_NS)
    i = k - nodes[0]
    s = ((flat - k * _NODE_NS) / _NODE_NS)[:, None]  # in [0, 1)
    h = float(NODE_STEP_S)
    s2, s3 = s * s, s * s * s
    out = ((2 * s3 - 3 * s2 + 1) * p[i] + (s3 - 2 * s2 + s) * h * v[i]
           + (-2 * s3 + 3 * s2) * p[i + 1] + (s3 - s2) * h * v[i + 1])
    return out.reshape(t.shape + (3,))


def sun_direction_I(tai_ns: ArrayLike, *, apparent: bool = False) -> NDArray[np.float64]:
    """Unit vector from the geocentre to the Sun in the GCRS, (..., 3) for tai_ns (...).

    apparent=False: geometric direction (error < 1e-7 rad). apparent=True: with the annual aberration
    of a geocentric observer (ERFA ab with the Earth's barycentric velocity, ~20 arcsec).
    """
    p = sun_position_I_m(tai_ns)
    dist = np.linalg.norm(p, axis=-1, keepdims=True)
    u = p / dist
    if not apparent:
        return u
    t = np.ravel(_as_tai(tai_ns)) + TT_MINUS_TAI_NS
    jd1, jd2 = _tt_jd(t)
    _, pvb = erfa.epv00(jd1, jd2)
    v_c = pvb["v"] / erfa.DC  # barycentric Earth velocity in units of c
    bm1 = np.sqrt(1.0 - np.sum(v_c * v_c, axis=-1))
    out = erfa.ab(u.reshape(-1, 3), v_c, dist.reshape(-1) / AU_M, bm1)
    return np.asarray(out).reshape(u.shape)


def sun_direction_from_I(r_I_m: ArrayLike, tai_ns: ArrayLike) -> NDArray[np.float64]:
    """Unit vector from a spacecraft at GCRS position r_I_m (..., 3) [m] to the Sun (geometric), (..., 3)."""
    r = np.asarray(r_I_m, dtype=np.float64)
    if r.ndim < 1 or r.shape[-1] != 3:
        raise ValueError(f"r_I_m must have shape (..., 3), got {r.shape}")
    d = sun_position_I_m(tai_ns) - r
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
