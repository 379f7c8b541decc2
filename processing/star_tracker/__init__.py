"""Paper 003 §1 (Avanesov et al. 2010): star-tracker accuracy from its own quaternions with the gyro
comparison and spectra (``accuracy``, §1.3-1.5), and the orbital attitude angles from the smoothed
attitude and a GNSS orbit (``orbital_attitude``, §1.6).
"""
