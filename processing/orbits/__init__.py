"""Orbits: two-body tools (``two_body``), GNSS orbit smoothing and fitting for 003 §1.6 (``gnss_orbit``;
noise, time-tag and fit checks in ``gnss_checks``),
and GPS/GLONASS/Galileo/BeiDou/QZSS broadcast ephemerides from their ICDs (``gnss_ephemeris``, 002).
"""
