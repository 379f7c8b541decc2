"""Direct (axial) dipole model of the geomagnetic field in the orbital frame: paper 002, eq. (2).

002, eq. (2), in the orbital frame of 002 (Z2 along the radius vector, away from the Earth; Y2 along
the orbital angular momentum; X2 = Y2 x Z2, transversal, on the side of the velocity):

    H_X2 = m / r^3 sin i cos u,    H_Y2 = m / r^3 cos i,    H_Z2 = -2 m / r^3 sin i sin u,

m = 8.1e6 T km^3 = 8.1e15 T m^3 (the paper's dipole moment, i.e. m = B_0 a^3 with B_0 the equatorial
surface field), i the inclination, u the argument of latitude. This is the field of a dipole along
the Earth's rotation axis pointing south (the Earth's field points north at the equator, down in the
northern hemisphere), exact for a circular orbit of radius r. 002 recommends the IGRF where accuracy
matters; the real dipole is tilted by ~9.5 deg and the higher degrees add up to ~20 % at LEO, so
directions from this model are off by up to ~15-20 deg (see tests).

The paper-004 orbital frame (X0 along the velocity, Y0 = -orbit normal, Z0 to the Earth's centre) is
X0 = X2, Y0 = -Y2, Z0 = -Z2: :func:`dipole_field_O004_nT`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.environment.igrf import IGRF_REFERENCE_RADIUS_M, IGRFCoefficients, igrf_gauss_coefficients_nT

__all__ = [
    "DIPOLE_MOMENT_002_T_M3",
    "dipole_field_O002_nT",
    "dipole_field_O004_nT",
    "dipole_moment_igrf_T_m3",
]

DIPOLE_MOMENT_002_T_M3 = 8.1e15
"""m of 002, eq. (2): 8.1e6 T km^3 in T m^3 (B_0 a^3; the IGRF-14 value for 2025 is ~7.6e15, see
:func:`dipole_moment_igrf_T_m3`)."""


def dipole_field_O002_nT(
    r_m: ArrayLike, inc_rad: ArrayLike, u_rad: ArrayLike, *, moment_T_m3: float = DIPOLE_MOMENT_002_T_M3
) -> NDArray[np.float64]:
    """Axial-dipole field in the 002 orbital frame (X2 transversal, Y2 orbit normal, Z2 radial out) [nT].

    r_m: orbit radius [m] (> 0); inc_rad: inclination; u_rad: argument of latitude; broadcast (...).
    moment_T_m3: dipole moment m [T m^3]. Returns (..., 3) nT (002, eq. 2).
    """
    r, i, u = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (r_m, inc_rad, u_rad)))
    if np.any(~(r > 0.0)):
        raise ValueError(f"r_m must be > 0, got min {np.min(r)!r}")
    k = 1e9 * moment_T_m3 / r**3
    return np.stack([k * np.sin(i) * np.cos(u), k * np.cos(i), -2.0 * k * np.sin(i) * np.sin(u)], axis=-1)


def dipole_field_O004_nT(
    r_m: ArrayLike, inc_rad: ArrayLike, u_rad: ArrayLike, *, moment_T_m3: float = DIPOLE_MOMENT_002_T_M3
) -> NDArray[np.float64]:
    """002 eq. (2) in the 004 orbital frame (X0 along the velocity, Y0 = -orbit normal, Z0 nadir) [nT].

    Same arguments as :func:`dipole_field_O002_nT`; components (H_X2, -H_Y2, -H_Z2).
    """
    return dipole_field_O002_nT(r_m, inc_rad, u_rad, moment_T_m3=moment_T_m3) * np.array([1.0, -1.0, -1.0])


def dipole_moment_igrf_T_m3(decimal_year: ArrayLike, coefficients: IGRFCoefficients | None = None) -> NDArray:
    """Moment m = a^3 sqrt(g10^2 + g11^2 + h11^2) [T m^3] of the IGRF's (tilted) dipole at the epochs (...)."""
    g, h = igrf_gauss_coefficients_nT(decimal_year, coefficients)
    b0_T = 1e-9 * np.sqrt(g[..., 1, 0] ** 2 + g[..., 1, 1] ** 2 + h[..., 1, 1] ** 2)
    return b0_T * IGRF_REFERENCE_RADIUS_M**3
