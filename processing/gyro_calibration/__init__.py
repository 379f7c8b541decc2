"""Gyro calibration: constant gyro offsets by Gauss-Newton on the integrated attitude (``bias_fit``,
``propagation``: paper 003 §2), and paper 000 (Somov & Butyrin 2016): drift observer
(``drift_observer``), misalignment and scale factor by QUEST (``alignment``) and the whole in-flight
calibration chain (``calibration``).
"""
