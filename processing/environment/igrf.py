"""IGRF-14 main geomagnetic field: vectorised spherical-harmonic synthesis, one epoch per sample.

Coefficients: the official IGRF-14 Gauss coefficients (IAGA Division V-MOD, 2024,
doi:10.5281/zenodo.14012302) as shipped in the ``IGRF14.shc`` file of the ``ppigrf`` package
(maintained by IAGA-VMOD; its 2030 column is the 2025 main field plus 5 years of the official
2025-2030 secular variation). The synthesis is our own so that every sample has its own epoch and
position (ppigrf evaluates every date at every position, an outer product) and no pandas is involved.

Model (the one of the official programs igrf14syn / pyIGRF):

- Gauss coefficients g_n^m(t), h_n^m(t) [nT], n = 1..13, linear in decimal year t between the
  5-year epochs 1900.0 .. 2025.0 and, from 2025.0 to 2030.0, the 2025 model plus the secular
  variation. Valid 1900.0 <= t <= 2030.0; outside, :class:`IGRFValueError` is raised.
- Potential V = a sum_n (a/r)^(n+1) sum_m (g cos m phi + h sin m phi) P_n^m(cos theta), a = 6371.2 km,
  Schmidt semi-normalised associated Legendre functions P_n^m, B = -grad V. Geocentric spherical
  components (B_r, B_theta, B_phi) = (up, south, east).
- Decimal year of an instant: UTC calendar year + elapsed fraction of that UTC year (days of 365 or
  366; the IGRF convention). One day is 0.0027 yr, over which the field changes by < 0.3 nT.

Frames: E = ITRF (Earth-fixed, WGS 84 axes). The IGRF is referred to the geographic (rotation) axes;
its error as a description of the real main field is ~10 nT at the ground and larger in the secular
variation years (crustal and external fields, up to a few hundred nT in LEO, are not in it).

Positions within 1e-9 rad of the geographic poles are moved 1e-9 rad away from the pole (the field is
continuous there; the change is below 1e-4 nT), so B_phi never divides by zero.
"""

from __future__ import annotations

import importlib.resources
from dataclasses import dataclass
from functools import lru_cache

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.time.julian_dates import tai_ns_to_jd
from processing.units import R_EARTH_M, WGS84_F

__all__ = [
    "IGRF_REFERENCE_RADIUS_M",
    "IGRFCoefficients",
    "IGRFValueError",
    "R_EARTH_M",
    "WGS84_F",
    "dcm_E_ned",
    "decimal_year_utc",
    "geodetic_from_E",
    "E_from_geodetic",
    "igrf14_coefficients",
    "igrf_field_E_nT",
    "igrf_field_E_nT_at",
    "igrf_field_geocentric_nT",
    "igrf_field_ned_nT",
    "igrf_gauss_coefficients_nT",
    "read_shc",
]

IGRF_REFERENCE_RADIUS_M = 6371.2e3
"""Geomagnetic reference radius a of the IGRF [m]."""
POLE_GUARD_RAD = 1e-9
"""Colatitudes closer than this to 0 or pi are moved to this distance from the pole."""

FloatArray = NDArray[np.float64]


class IGRFValueError(ValueError):
    """Bad input to the IGRF functions: wrong shape, epoch outside the model, non-positive radius."""


@dataclass(frozen=True)
class IGRFCoefficients:
    """Gauss coefficients of a spherical-harmonic main-field model on a grid of epochs.

    epochs_year: (K,) decimal years, increasing. g_nT, h_nT: (K, nmax+1, nmax+1), index [k, n, m]
    (zero where m > n, and h[:, n, 0] = 0). Linear interpolation in time between epochs.
    source: text naming where the numbers came from (reports print it).
    """

    epochs_year: FloatArray
    g_nT: FloatArray
    h_nT: FloatArray
    nmax: int
    source: str

    @property
    def valid_from_year(self) -> float:
        return float(self.epochs_year[0])

    @property
    def valid_to_year(self) -> float:
        return float(self.epochs_year[-1])


def read_shc(text: str, source: str) -> IGRFCoefficients:
    """Parse a ``.shc`` coefficient file (the format of the IGRF/ppigrf and ESA VirES files).

    Lines starting with '#' are comments; the first other line holds N_MIN N_MAX N_TIMES SP_ORDER
    N_STEPS [start end]; the next the N_TIMES epochs (decimal years); then one line per coefficient:
    n, m, then N_TIMES values [nT], with m < 0 meaning h_n^|m|. Raises IGRFValueError on malformed text.
    """
    rows = [line.split() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if len(rows) < 3:
        raise IGRFValueError(f"SHC text needs a header line, an epoch line and coefficients; got {len(rows)} lines")
    try:
        n_min, n_max, n_times = (int(x) for x in rows[0][:3])
        epochs = np.array([float(x) for x in rows[1]])
        coeffs = [(int(r[0]), int(r[1]), np.array([float(x) for x in r[2:]])) for r in rows[2:]]
    except (ValueError, IndexError) as exc:
        raise IGRFValueError(f"malformed SHC text: {exc}") from exc
    if epochs.size != n_times or np.any(np.diff(epochs) <= 0):
        raise IGRFValueError(f"SHC epoch line must hold {n_times} increasing epochs, got {epochs.tolist()}")
    g = np.zeros((n_times, n_max + 1, n_max + 1))
    h = np.zeros_like(g)
    for n, m, values in coeffs:
        if values.size != n_times or not (n_min <= n <= n_max) or abs(m) > n:
            raise IGRFValueError(f"SHC coefficient line n={n} m={m} with {values.size} values is malformed")
        (g if m >= 0 else h)[:, n, abs(m)] = values
    return IGRFCoefficients(epochs_year=epochs, g_nT=g, h_nT=h, nmax=n_max, source=source)


@lru_cache(maxsize=1)
def igrf14_coefficients() -> IGRFCoefficients:
    """The official IGRF-14 coefficients (1900.0-2030.0, degree 13) from the ppigrf package's IGRF14.shc.

    Read once and cached (immutable). Raises IGRFValueError if the installed file is not IGRF-14.
    """
    text = (importlib.resources.files("ppigrf") / "IGRF14.shc").read_text()
    coeffs = read_shc(text, source="IGRF-14 (IAGA V-MOD 2024, doi:10.5281/zenodo.14012302), ppigrf IGRF14.shc")
    if "IGRF 14" not in text.splitlines()[0] or coeffs.valid_to_year != 2030.0 or coeffs.nmax != 13:
        raise IGRFValueError("the ppigrf package does not carry IGRF-14 coefficients (1900-2030, degree 13)")
    return coeffs


def _as_float(x: ArrayLike, name: str) -> FloatArray:
    return np.asarray(x, dtype=np.float64)


def igrf_gauss_coefficients_nT(
    decimal_year: ArrayLike, coefficients: IGRFCoefficients | None = None
) -> tuple[FloatArray, FloatArray]:
    """g_n^m, h_n^m [nT] at each epoch: arrays (..., nmax+1, nmax+1) indexed [..., n, m].

    decimal_year: (...) years, within the model's validity (IGRF-14: 1900.0-2030.0), else
    IGRFValueError naming the bad rows. Linear interpolation between the model epochs.
    """
    c = igrf14_coefficients() if coefficients is None else coefficients
    k, w = _epoch_weights(_as_float(decimal_year, "decimal_year"), c)
    w = w[..., None, None]
    g = (1.0 - w) * c.g_nT[k] + w * c.g_nT[k + 1]
    h = (1.0 - w) * c.h_nT[k] + w * c.h_nT[k + 1]
    return g, h


def _epoch_weights(t: FloatArray, c: IGRFCoefficients) -> tuple[NDArray[np.intp], FloatArray]:
    """Index k of the model epoch at or before t and the interpolation weight w in [0, 1]."""
    bad = ~((t >= c.valid_from_year) & (t <= c.valid_to_year))
    if np.any(bad):
        idx = np.flatnonzero(np.ravel(bad))
        raise IGRFValueError(
            f"{idx.size} of {t.size} epochs outside the model's validity {c.valid_from_year}-{c.valid_to_year} "
            f"(first at flat index {int(idx[0])}: {np.ravel(t)[idx[0]]!r})"
        )
    k = np.clip(np.searchsorted(c.epochs_year, t, side="right") - 1, 0, c.epochs_year.size - 2)
    return k, (t - c.epochs_year[k]) / (c.epochs_year[k + 1] - c.epochs_year[k])


def _degree_order(nmax: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Degrees n and orders m of the (nmax+1)(nmax+2)/2 - 1 terms with 1 <= n <= nmax, 0 <= m <= n."""
    pairs = [(n, m) for n in range(1, nmax + 1) for m in range(n + 1)]
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


def _legendre(theta: FloatArray, nmax: int) -> tuple[FloatArray, FloatArray]:
    """Schmidt semi-normalised P_n^m(cos theta) and dP_n^m/dtheta as (K, N) arrays, rows in the order
    of :func:`_degree_order`.

    Recursions (e.g. Langel 1987, Winch et al. 2005): P_1^1 = sin, P_n^n = sqrt((2n-1)/(2n)) sin P_{n-1}^{n-1}
    (n >= 2), P_n^m = ((2n-1) cos P_{n-1}^m - sqrt((n-1)^2 - m^2) P_{n-2}^m) / sqrt(n^2 - m^2), and
    their theta derivatives.
    """
    s, c = np.sin(theta), np.cos(theta)
    p: dict[tuple[int, int], FloatArray] = {(0, 0): np.ones_like(theta)}
    dp: dict[tuple[int, int], FloatArray] = {(0, 0): np.zeros_like(theta)}
    zero = np.zeros_like(theta)
    for n in range(1, nmax + 1):
        if n == 1:
            p[1, 1], dp[1, 1] = s, c
        else:
            k = np.sqrt((2.0 * n - 1.0) / (2.0 * n))
            p[n, n] = k * s * p[n - 1, n - 1]
            dp[n, n] = k * (c * p[n - 1, n - 1] + s * dp[n - 1, n - 1])
        for m in range(n):
            a = (2.0 * n - 1.0) / np.sqrt(n * n - m * m)
            b = np.sqrt(((n - 1.0) ** 2 - m * m) / (n * n - m * m))
            p2, dp2 = p.get((n - 2, m), zero), dp.get((n - 2, m), zero)
            p[n, m] = a * c * p[n - 1, m] - b * p2
            dp[n, m] = a * (c * dp[n - 1, m] - s * p[n - 1, m]) - b * dp2
    nn, mm = _degree_order(nmax)
    return (np.stack([p[n, m] for n, m in zip(nn, mm, strict=True)]),
            np.stack([dp[n, m] for n, m in zip(nn, mm, strict=True)]))


def igrf_field_geocentric_nT(
    decimal_year: ArrayLike,
    r_m: ArrayLike,
    colat_rad: ArrayLike,
    lon_rad: ArrayLike,
    *,
    max_degree: int = 13,
    coefficients: IGRFCoefficients | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """IGRF field in geocentric spherical components (B_r, B_theta, B_phi) [nT] (up, south, east).

    decimal_year, r_m (geocentric radius, m, > 0), colat_rad (geocentric colatitude), lon_rad (east
    longitude): broadcast to a common shape (...); each sample is evaluated at its own epoch.
    max_degree: truncation degree 1..nmax. Returns three (...) arrays.
    """
    c = igrf14_coefficients() if coefficients is None else coefficients
    if not 1 <= max_degree <= c.nmax:
        raise IGRFValueError(f"max_degree must be in 1..{c.nmax}, got {max_degree}")
    try:
        t, r, th, ph = np.broadcast_arrays(*(_as_float(x, "") for x in (decimal_year, r_m, colat_rad, lon_rad)))
    except ValueError as exc:
        raise IGRFValueError(f"decimal_year, r_m, colat_rad, lon_rad must broadcast: {exc}") from None
    shape = t.shape
    t, r, th, ph = (np.ravel(x) for x in (t, r, th, ph))
    if np.any(~(r > 0.0)):
        raise IGRFValueError(f"r_m must be > 0, got min {np.min(r)!r}")
    th = np.clip(th, POLE_GUARD_RAD, np.pi - POLE_GUARD_RAD)
    nn, mm = _degree_order(max_degree)
    k, w = _epoch_weights(t, c)
    g_ep, h_ep = c.g_nT[:, nn, mm].T, c.h_nT[:, nn, mm].T  # (K, epochs)
    g = (1.0 - w) * g_ep[:, k] + w * g_ep[:, k + 1]  # (K, N)
    h = (1.0 - w) * h_ep[:, k] + w * h_ep[:, k + 1]
    p, dp = _legendre(th, max_degree)  # (K, N)
    m = np.arange(max_degree + 1)[:, None]
    cos_mp, sin_mp = np.cos(m * ph)[mm], np.sin(m * ph)[mm]  # (K, N)
    ratio = IGRF_REFERENCE_RADIUS_M / r
    powers = np.cumprod(np.broadcast_to(ratio, (max_degree + 2, ratio.size)), axis=0)  # (a/r)^(j+1)
    ar = ratio * powers[nn]  # (a/r)^(n+2), (K, N)
    cs = (g * cos_mp + h * sin_mp) * ar
    sc = mm[:, None] * (h * cos_mp - g * sin_mp) * ar
    b_r = np.sum((nn[:, None] + 1.0) * cs * p, axis=0)
    b_t = -np.sum(cs * dp, axis=0)
    b_p = -np.sum(sc * p, axis=0) / np.sin(th)
    return b_r.reshape(shape), b_t.reshape(shape), b_p.reshape(shape)


def decimal_year_utc(tai_ns: ArrayLike) -> FloatArray:
    """Decimal year of instants (int64 tai_ns): UTC year + elapsed fraction of that UTC year.

    The IGRF's time argument. Returns (...) float years. UTC before 1972 is not supported (TimeValueError).
    """
    jd1, jd2 = tai_ns_to_jd(tai_ns, "utc")
    year = np.asarray(erfa.jd2cal(jd1, jd2)[0])
    a1, a2 = erfa.cal2jd(year, 1, 1)
    b1, b2 = erfa.cal2jd(year + 1, 1, 1)
    return year + ((jd1 - a1 - a2) + jd2) / ((b1 + b2) - (a1 + a2))


def _check_vectors(r_E_m: ArrayLike, name: str) -> FloatArray:
    r = _as_float(r_E_m, name)
    if r.ndim < 1 or r.shape[-1] != 3:
        raise IGRFValueError(f"{name} must have shape (..., 3), got {r.shape}")
    return r


def igrf_field_E_nT(
    r_E_m: ArrayLike, tai_ns: ArrayLike, *, max_degree: int = 13, coefficients: IGRFCoefficients | None = None
) -> FloatArray:
    """IGRF-14 main field at Earth-fixed positions, as ITRF (E) components [nT].

    r_E_m: (..., 3) ITRF positions [m] (geocentric, |r| > 0); tai_ns: (...) int64 instants, broadcast
    against the leading dimensions. Returns B_E (..., 3) nT, e.g. (N, 3) for N samples.
    """
    r = _check_vectors(r_E_m, "r_E_m")
    t = np.asarray(tai_ns)
    try:
        shape = np.broadcast_shapes(r.shape[:-1], t.shape)
    except ValueError:
        raise IGRFValueError(
            f"r_E_m {r.shape} and tai_ns {t.shape} must broadcast (expected (..., 3) and (...))"
        ) from None
    year = decimal_year_utc(np.broadcast_to(t, shape))
    return igrf_field_E_nT_at(r, year, max_degree=max_degree, coefficients=coefficients)


def igrf_field_E_nT_at(
    r_E_m: ArrayLike, decimal_year: ArrayLike, *, max_degree: int = 13, coefficients: IGRFCoefficients | None = None
) -> FloatArray:
    """As :func:`igrf_field_E_nT` with the epoch given as decimal years (...) instead of tai_ns."""
    r = _check_vectors(r_E_m, "r_E_m")
    year = _as_float(decimal_year, "decimal_year")
    try:
        shape = np.broadcast_shapes(r.shape[:-1], year.shape)
    except ValueError:
        raise IGRFValueError(
            f"r_E_m {r.shape} and decimal_year {year.shape} must broadcast (expected (..., 3) and (...))"
        ) from None
    r = np.broadcast_to(r, shape + (3,))
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    rho = np.hypot(x, y)
    colat = np.arctan2(rho, z)
    lon = np.arctan2(y, x)
    b_r, b_t, b_p = igrf_field_geocentric_nT(
        np.broadcast_to(year, shape), np.hypot(rho, z), colat, lon, max_degree=max_degree, coefficients=coefficients
    )
    ct, st = np.cos(colat), np.sin(colat)
    cl, sl = np.cos(lon), np.sin(lon)
    bx = b_r * st * cl + b_t * ct * cl - b_p * sl
    by = b_r * st * sl + b_t * ct * sl + b_p * cl
    bz = b_r * ct - b_t * st
    return np.stack([bx, by, bz], axis=-1)


def geodetic_from_E(r_E_m: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """WGS 84 geodetic latitude [rad], east longitude [rad] and height [m] of ITRF positions (..., 3).

    ERFA gc2gd (exact closed form, Fukushima 2006). Returns three (...) arrays.
    """
    r = _check_vectors(r_E_m, "r_E_m")
    lon, lat, height = erfa.gc2gd(1, r)
    return np.asarray(lat), np.asarray(lon), np.asarray(height)


def E_from_geodetic(lat_rad: ArrayLike, lon_rad: ArrayLike, height_m: ArrayLike) -> FloatArray:
    """ITRF position (..., 3) [m] of WGS 84 geodetic latitude, east longitude [rad] and height [m] (erfa.gd2gc)."""
    lat, lon, hgt = np.broadcast_arrays(*(_as_float(x, "") for x in (lat_rad, lon_rad, height_m)))
    return np.asarray(erfa.gd2gc(1, lon, lat, hgt))


def dcm_E_ned(lat_rad: ArrayLike, lon_rad: ArrayLike) -> FloatArray:
    """dcm_E_NED (..., 3, 3): columns are the local north, east and down (geodetic) axes in ITRF.

    v_E = dcm_E_ned @ v_NED; v_NED = dcm_E_ned^T @ v_E. lat_rad geodetic latitude, lon_rad east longitude.
    """
    lat, lon = np.broadcast_arrays(_as_float(lat_rad, ""), _as_float(lon_rad, ""))
    sf, cf, sl, cl = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    north = np.stack([-sf * cl, -sf * sl, cf], axis=-1)
    east = np.stack([-sl, cl, np.zeros_like(sl)], axis=-1)
    down = np.stack([-cf * cl, -cf * sl, -sf], axis=-1)
    return np.stack([north, east, down], axis=-1)


def igrf_field_ned_nT(
    lat_rad: ArrayLike,
    lon_rad: ArrayLike,
    height_m: ArrayLike,
    tai_ns: ArrayLike,
    *,
    max_degree: int = 13,
    coefficients: IGRFCoefficients | None = None,
) -> FloatArray:
    """IGRF-14 field in local geodetic north, east, down components (X, Y, Z of geomagnetism) [nT].

    lat_rad (WGS 84 geodetic), lon_rad, height_m (above the ellipsoid), tai_ns: broadcast (...).
    Returns (..., 3).
    """
    r_E = E_from_geodetic(lat_rad, lon_rad, height_m)
    b_E = igrf_field_E_nT(r_E, tai_ns, max_degree=max_degree, coefficients=coefficients)
    lat, lon = np.broadcast_arrays(_as_float(lat_rad, ""), _as_float(lon_rad, ""))
    return np.einsum("...ji,...j->...i", dcm_E_ned(lat, lon), b_E)
