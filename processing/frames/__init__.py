"""Reference frames: Earth orientation GCRS <-> ITRS and other inertial frames, IAU 2006/2000A via ERFA
(``earth_orientation``), its interpolated form for long dense series (``earth_rotation_interp``), IERS
EOP tables (``eop``) and orbital frames from position and velocity (``orbital``: the 003 and 004
definitions).
"""
