"""Paper 004 (Melashchenko & Ryzhkov 2008): the gyroless EKF and MEKF on rigid-body dynamics (``ekf``),
their RTS smoother (``rts_smoother``), the estimation chain over a window (``estimation``) and the
magnetic controllers (``magnetic_control``).
"""
