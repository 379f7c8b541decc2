"""GNSS systems and the validity of their broadcast ephemeris records (shared by the RINEX reader in
processing.formats.rinex_nav and the ephemeris evaluation in processing.orbits.gnss_ephemeris).

System letters as in RINEX: G GPS, E Galileo, J QZSS, C BeiDou, I NavIC, R GLONASS, S SBAS.
"""

KEPLER_SYSTEMS = ("G", "E", "J", "C", "I")
"""Systems whose broadcast records are Keplerian elements (IS-GPS-200 style)."""
STATE_SYSTEMS = ("R", "S")
"""Systems whose broadcast records are position/velocity/acceleration states (GLONASS, SBAS)."""
DEFAULT_MAX_AGE_S = {"G": 7200.0, "J": 7200.0, "E": 14400.0, "C": 3600.0, "I": 7200.0, "R": 1800.0, "S": 600.0}
"""Largest |t - t_ref| at which a record is used, per system: half the GPS 4-hour fit interval, the
Galileo 4-hour validity, BeiDou's hourly updates, GLONASS's 30-minute tb spacing (the ICD's +-15 min
nominal, doubled so that one missing record does not leave a hole), SBAS's 5-minute messages."""
