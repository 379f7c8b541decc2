"""Time scales: UTC (with leap seconds), TAI, GPS and TT readings to and from the continuous int64
TAI-nanosecond count used everywhere inside the service, and Julian dates for ERFA (``timescales``).
"""
