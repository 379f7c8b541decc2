"""Reference kind ``eop_finals2000a``: IERS Earth orientation parameters (finals2000A format).

Upload a ``finals2000A.all`` / ``.data`` / ``.daily`` file (IERS Rapid Service/Prediction Centre);
jobs that declare this kind (e.g. orbital_attitude) get the newest data set covering their window
and interpolate UT1-UTC and polar motion from it (processing/frames/eop.py). Without one, jobs use zero
EOP and say so in their report.
"""

from __future__ import annotations

from app.reference.registry import ReferenceKind
from processing.frames.eop import parse_finals2000a_reference

KINDS = {
    "eop_finals2000a": ReferenceKind(
        "eop_finals2000a", parse_finals2000a_reference,
        "IERS finals2000A Earth orientation parameters (polar motion, UT1-UTC, dX/dY); Bulletin B where given, "
        "else Bulletin A (final or predicted)"),
}
