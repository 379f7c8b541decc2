"""The real data sets the tests use, kept in the repository's ``data/`` folder (see data/README.md)."""

from __future__ import annotations

from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "data"
GNSS_NAV = DATA / "gnss-nav"
GRACEFO = DATA / "gracefo-l1b-2023-06-01"
REFERENCE = Path(__file__).resolve().parent / "data"
"""Small golden-reference files of the unit tests (tests/data/README.md)."""
