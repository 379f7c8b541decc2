"""Every unit conversion and physical constant of the service, defined once.

Names say the direction: ``RAD_PER_ARCSEC`` multiplies arcseconds into radians, ``ARCSEC_PER_RAD``
radians into arcseconds. Inside the service everything is SI (rad, rad/s, m, s, T or nT stated);
degrees, arcseconds and hours appear only at the edges (reports, API summaries), converted here.
Time-scale offsets (TT - TAI, TAI - GPS) live with the time scales in processing.time.timescales, and
the constants a GNSS interface control document fixes live with that ICD's code
(processing.orbits.gnss_ephemeris).
"""

from __future__ import annotations

import math

# -- time -----------------------------------------------------------------------------------------
NS_PER_S = 1_000_000_000
S_PER_DAY = 86_400
NS_PER_DAY = S_PER_DAY * NS_PER_S
S_PER_HOUR = 3_600

# -- angles ---------------------------------------------------------------------------------------
RAD_PER_DEG = math.pi / 180.0
DEG_PER_RAD = 180.0 / math.pi
RAD_PER_ARCSEC = math.pi / 648_000.0
ARCSEC_PER_RAD = 648_000.0 / math.pi
RAD_PER_MAS = RAD_PER_ARCSEC / 1_000.0

# -- angular rates --------------------------------------------------------------------------------
DEG_H_PER_RAD_S = DEG_PER_RAD * S_PER_HOUR
"""rad/s -> deg/h (gyro bias and drift in reports)."""
RAD_S_PER_DEG_H = 1.0 / DEG_H_PER_RAD_S

# -- magnetic field -------------------------------------------------------------------------------
NT_PER_T = 1e9

# -- Earth and Sun --------------------------------------------------------------------------------
MU_EARTH_M3_S2 = 3.986004418e14
"""Earth's gravitational parameter GM (IERS Conventions 2010, EGM2008/WGS 84 value)."""
R_EARTH_M = 6_378_137.0
"""Equatorial radius (WGS 84 semi-major axis)."""
WGS84_F = 1.0 / 298.257223563
"""WGS 84 flattening."""
J2_EARTH = 1.08262668e-3
"""Earth's second zonal harmonic (EGM96, unnormalised)."""
OMEGA_EARTH_RAD_S = 7.292115e-5
"""Nominal mean angular velocity of the Earth (IERS Conventions 2010, table 1.1)."""
AU_M = 149_597_870_700.0
"""Astronomical unit (IAU 2012 resolution B2)."""
TROPICAL_YEAR_DAYS = 365.2421897
