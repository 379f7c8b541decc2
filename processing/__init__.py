"""Pure numerics of the attitude telemetry service: arrays and frozen dataclasses in and out, no I/O.

Packages by domain (conventions in DESIGN.md: scalar-first Hamilton quaternions q_AB, SI units, TAI ns):

- ``units``: every unit and physical constant, once.
- ``attitude``: rotations, MRP kinematics, Wahba solvers, rigid-body dynamics.
- ``time``: UTC/TAI/GPS/TT readings and the continuous TAI-nanosecond count.
- ``frames``: Earth orientation (GCRS/ITRS, IAU 2006/2000A), EOP tables, orbital frames.
- ``orbits``: two-body tools, GNSS orbit smoothing, broadcast ephemerides.
- ``signal``: sine-series smoothing, spectra and lines, the two-pass filter.
- ``environment``: geomagnetic field, Sun, Earth shadow.
- ``estimation``: filter consistency (NIS, NEES, whiteness).
- ``star_tracker`` (paper 003 §1), ``gyro_calibration`` (003 §2, 000), ``screening`` and
  ``vector_attitude`` (002), ``gyroless`` (004): the papers' estimators.
- ``formats``: CCSDS, GRACE-FO Level-1B, RINEX readers and writers (bytes in, arrays out).
- ``simulate``: scenario generators with known truth (tests and demo).
- ``streams``: the telemetry stream schema (also imported by storage); ``tasks``: the job contract.
"""
