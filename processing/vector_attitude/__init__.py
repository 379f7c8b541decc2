"""Paper 002 attitude without a star tracker: antenna axis from GNSS visibility (``antenna_axis``,
eq. 5-7), strongly coupled vector attitude by Wahba's problem (``determination``, eq. 8-9) and the
loosely coupled Newton solution (``loosely_coupled``, eq. 10-14).
"""
