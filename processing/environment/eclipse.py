"""Earth shadow of a spacecraft: conical (umbra/penumbra, visible fraction of the solar disc) and
cylindrical models.

Conical model (the default for the service; Montenbruck & Gill, Satellite Orbits, 2000, §3.4.2):
spherical Earth of radius ``earth_radius_m`` (default WGS 84 equatorial, 6378.137 km, optionally
raised by an atmosphere height) and Sun of radius 695 700 km, seen from the spacecraft as discs of
apparent radii a = asin(R_sun / |s - r|) and b = asin(R_earth / |r|), separated by
c = angle between -r and s - r. Visible fraction of the solar disc nu: 1 if c >= a + b (sunlit),
0 if c <= b - a (umbra), 1 - b^2/a^2 if c <= a - b (annular, impossible for LEO), otherwise
1 - A / (pi a^2) with the overlap area A of the two discs (penumbra).
The oblateness of the Earth is ignored: it moves shadow entry and exit by a few seconds in LEO.

Cylindrical model (:func:`in_shadow_cylindrical`): the shadow is the cylinder of radius R_earth behind
the Earth along the Sun direction; no penumbra. It is what many on-board codes and paper 002's
"shadowed by the Earth" test use; at LEO it puts the shadow boundary within the penumbra (the
penumbra lasts ~8-10 s per crossing at 650 km).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.environment.sun import SUN_RADIUS_M
from processing.units import R_EARTH_M

__all__ = [
    "PENUMBRA",
    "SUNLIT",
    "UMBRA",
    "eclipse_state",
    "in_shadow_cylindrical",
    "sunlit_fraction",
]

SUNLIT, PENUMBRA, UMBRA = 0, 1, 2
"""Codes returned by :func:`eclipse_state` (annular eclipses count as PENUMBRA)."""


def _vectors(r_I_m: ArrayLike, r_sun_I_m: ArrayLike) -> tuple[NDArray, NDArray]:
    r = np.asarray(r_I_m, dtype=np.float64)
    s = np.asarray(r_sun_I_m, dtype=np.float64)
    if r.ndim < 1 or r.shape[-1] != 3 or s.ndim < 1 or s.shape[-1] != 3:
        raise ValueError(f"r_I_m and r_sun_I_m must have shape (..., 3), got {r.shape} and {s.shape}")
    try:
        np.broadcast_shapes(r.shape, s.shape)
    except ValueError:
        raise ValueError(f"r_I_m {r.shape} and r_sun_I_m {s.shape} must broadcast") from None
    return r, s


def sunlit_fraction(
    r_I_m: ArrayLike,
    r_sun_I_m: ArrayLike,
    *,
    earth_radius_m: float = R_EARTH_M,
    sun_radius_m: float = SUN_RADIUS_M,
) -> NDArray[np.float64]:
    """Visible fraction (0..1) of the solar disc from positions r_I_m (..., 3) [m] (conical model).

    r_sun_I_m: geocentric Sun position(s) (..., 3) [m] in the same frame (e.g. sun_position_I_m).
    Returns (...) with 1 = full sunlight, 0 = umbra.
    """
    r, s = _vectors(r_I_m, r_sun_I_m)
    d = s - r
    dist_r = np.linalg.norm(r, axis=-1)
    dist_d = np.linalg.norm(d, axis=-1)
    a = np.arcsin(np.clip(sun_radius_m / dist_d, -1.0, 1.0))
    b = np.arcsin(np.clip(earth_radius_m / dist_r, -1.0, 1.0))
    cos_c = -np.sum(r * d, axis=-1) / (dist_r * dist_d)
    c = np.arccos(np.clip(cos_c, -1.0, 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (c * c + a * a - b * b) / (2.0 * c)
        y = np.sqrt(np.maximum(a * a - x * x, 0.0))
        area = a * a * np.arccos(np.clip(x / a, -1.0, 1.0)) + b * b * np.arccos(np.clip((c - x) / b, -1.0, 1.0)) - c * y
        partial = 1.0 - area / (np.pi * a * a)
    nu = np.where(c >= a + b, 1.0, np.where(c <= b - a, 0.0, np.where(c <= a - b, 1.0 - (b * b) / (a * a), partial)))
    return np.clip(nu, 0.0, 1.0)


def eclipse_state(
    r_I_m: ArrayLike,
    r_sun_I_m: ArrayLike,
    *,
    earth_radius_m: float = R_EARTH_M,
    sun_radius_m: float = SUN_RADIUS_M,
) -> NDArray[np.int8]:
    """SUNLIT (0), PENUMBRA (1) or UMBRA (2) per position (conical model), int8 (...)."""
    nu = sunlit_fraction(r_I_m, r_sun_I_m, earth_radius_m=earth_radius_m, sun_radius_m=sun_radius_m)
    return np.where(nu >= 1.0, SUNLIT, np.where(nu <= 0.0, UMBRA, PENUMBRA)).astype(np.int8)


def in_shadow_cylindrical(
    r_I_m: ArrayLike, sun_dir_I: ArrayLike, *, earth_radius_m: float = R_EARTH_M
) -> NDArray[np.bool_]:
    """True where r_I_m (..., 3) [m] lies in the cylindrical Earth shadow along sun_dir_I (..., 3).

    sun_dir_I need not be normalised. Shadow: r . s_hat < 0 and |r - (r . s_hat) s_hat| < R_earth.
    """
    r, s = _vectors(r_I_m, sun_dir_I)
    s_hat = s / np.linalg.norm(s, axis=-1, keepdims=True)
    along = np.sum(r * s_hat, axis=-1)
    perp = np.linalg.norm(r - along[..., None] * s_hat, axis=-1)
    return (along < 0.0) & (perp < earth_radius_m)
