"""Paper 002 screening (Grigoryeva & Kramlikh 2013, eq. 15-17) and telemetry quality: rejection
criteria (``criteria``), per-sample flags (``flags``), the building blocks they share (``tools``) and
coverage/gaps of any stream (``coverage``).
"""
