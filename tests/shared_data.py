"""Where the project's shared real data live: ``shared/data`` beside the repository (as in CI),
or ATTITUDE_SHARED_DATA when set."""

from __future__ import annotations

import os
from pathlib import Path

SHARED_DATA = Path(os.environ.get("ATTITUDE_SHARED_DATA")
                   or Path(__file__).resolve().parents[2] / "shared" / "data")
GNSS_NAV = SHARED_DATA / "gnss-nav"
GRACEFO = SHARED_DATA / "gracefo-l1b-2023-06-01"
