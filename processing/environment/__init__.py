"""Environment models along an orbit: geomagnetic field, Sun, Earth shadow.

- :mod:`processing.environment.igrf`: IGRF-14 main field, vectorised per sample
  (``igrf_field_E_nT(r_E_m, tai_ns) -> B_E`` in ITRF components, geocentric and NED variants,
  WGS 84 geodetic helpers).
- :mod:`processing.environment.dipole`: the direct dipole of paper 002, eq. (2), in orbital frames.
- :mod:`processing.environment.sun`: Sun position/direction in the GCRS (ERFA epv00, < 1e-7 rad).
- :mod:`processing.environment.eclipse`: conical (umbra/penumbra) and cylindrical Earth shadow.

Pure numpy/ERFA, no I/O beyond reading the packaged IGRF-14 coefficient file once.
"""

from processing.environment.dipole import (
    DIPOLE_MOMENT_002_T_M3,
    dipole_field_O002_nT,
    dipole_field_O004_nT,
    dipole_moment_igrf_T_m3,
)
from processing.environment.eclipse import (
    PENUMBRA,
    SUNLIT,
    UMBRA,
    eclipse_state,
    in_shadow_cylindrical,
    sunlit_fraction,
)
from processing.environment.igrf import (
    IGRFValueError,
    decimal_year_utc,
    geodetic_from_E,
    igrf14_coefficients,
    igrf_field_E_nT,
    igrf_field_E_nT_at,
    igrf_field_geocentric_nT,
    igrf_field_ned_nT,
)
from processing.environment.sun import SUN_RADIUS_M, sun_direction_from_I, sun_direction_I, sun_position_I_m
from processing.units import AU_M

__all__ = [
    "AU_M",
    "DIPOLE_MOMENT_002_T_M3",
    "IGRFValueError",
    "PENUMBRA",
    "SUNLIT",
    "SUN_RADIUS_M",
    "UMBRA",
    "decimal_year_utc",
    "dipole_field_O002_nT",
    "dipole_field_O004_nT",
    "dipole_moment_igrf_T_m3",
    "eclipse_state",
    "geodetic_from_E",
    "igrf14_coefficients",
    "igrf_field_E_nT",
    "igrf_field_E_nT_at",
    "igrf_field_geocentric_nT",
    "igrf_field_ned_nT",
    "in_shadow_cylindrical",
    "sun_direction_I",
    "sun_direction_from_I",
    "sun_position_I_m",
    "sunlit_fraction",
]
