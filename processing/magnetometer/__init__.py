"""Magnetometer calibration: the error model (model.py) and its attitude-independent estimate from |B|
matching against the field model (calibration.py)."""
