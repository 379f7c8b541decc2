"""Orbits: two-body tools (``two_body``), GNSS orbit smoothing and fitting for 003 §1.6 (``gnss_orbit``),
and GPS/GLONASS/Galileo/BeiDou/QZSS broadcast ephemerides from their ICDs (``gnss_ephemeris``, 002).
"""
