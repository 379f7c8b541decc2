"""Reference kinds for paper 002: GNSS broadcast ephemerides and a reference orbit.

- ``rinex_nav``: a RINEX 2 (GPS or GLONASS) or RINEX 3 (mixed) navigation file
  (processing/formats/rinex_nav.py); the vector-attitude job computes the positions of the invisible
  navigation satellites from it (002, eqs. 5-7) and the screening checks visibility against it.
- ``reference_orbit``: the control centre's orbit that 002 eq. 15 compares the energy integral with.
  A CCSDS OEM (KVN, processing/formats/ccsds_odm.py; any segments of one frame family, converted to m)
  or a CSV with the header ``time,x,y,z,vx,vy,vz`` (ISO 8601 UTC times, metres and m/s) and an optional
  first line ``# frame: ITRF`` (default) or ``# frame: GCRF`` (any inertial frame name).
  Columns: time_tai_ns, x, y, z, vx, vy, vz; details: frame, earth_fixed, source.
"""

from __future__ import annotations

import io

import numpy as np
import pandas as pd

from app.reference.registry import ReferenceKind
from processing.formats.ccsds_odm import is_earth_fixed, parse_oem
from processing.formats.rinex_nav import parse_rinex_nav_reference
from processing.tasks import ParsedReference
from processing.time import timescales

ORBIT_COLUMNS = ("x", "y", "z", "vx", "vy", "vz")


def _from_oem(raw: bytes) -> ParsedReference:
    oem = parse_oem(raw)
    if not oem.segments:
        raise ValueError("the OEM has no data segment")
    frames = {s.ref_frame for s in oem.segments}
    earth_fixed = {is_earth_fixed(f) for f in frames}
    if len(earth_fixed) != 1:
        raise ValueError(f"OEM segments mix Earth-fixed and inertial frames: {sorted(frames)}")
    t = np.concatenate([s.time_tai_ns for s in oem.segments]).astype(np.int64)
    r = np.concatenate([s.position_m for s in oem.segments])
    v = np.concatenate([s.velocity_m_s for s in oem.segments])
    return _orbit(t, r, v, sorted(frames)[0], earth_fixed.pop(), "CCSDS OEM " + oem.version)


def _from_csv(raw: bytes) -> ParsedReference:
    text = raw.decode("utf-8", errors="replace")
    frame = "ITRF"
    first = text.lstrip().splitlines()[0] if text.strip() else ""
    if first.startswith("#") and "frame" in first.lower():
        frame = first.split(":", 1)[-1].split("=", 1)[-1].strip() or "ITRF"
    try:
        df = pd.read_csv(io.StringIO(text), comment="#", skipinitialspace=True)
    except (ValueError, pd.errors.ParserError) as exc:
        raise ValueError(f"expected a CSV with the header time,x,y,z,vx,vy,vz: {exc}") from None
    df.columns = [str(c).strip().lower() for c in df.columns]
    missing = [c for c in ("time", *ORBIT_COLUMNS) if c not in df.columns]
    if missing:
        raise ValueError(f"expected the columns time,x,y,z,vx,vy,vz (m, m/s, ISO UTC times); missing {missing}")
    t = timescales.iso_to_tai_ns(df["time"].astype(str).to_numpy())
    values = df[list(ORBIT_COLUMNS)].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values).all(axis=1)
    if np.any(bad):
        raise ValueError(f"{int(bad.sum())} rows have non-numeric x..vz, first at data row {int(np.argmax(bad)) + 1}")
    return _orbit(t, values[:, :3], values[:, 3:], frame, is_earth_fixed(frame) or frame.upper() == "ITRF", "CSV")


def _orbit(t: np.ndarray, r: np.ndarray, v: np.ndarray, frame: str, earth_fixed: bool, source: str
           ) -> ParsedReference:
    if t.size < 4:
        raise ValueError(f"a reference orbit needs at least 4 states, got {t.size}")
    order = np.argsort(t, kind="stable")
    t, r, v = t[order], r[order], v[order]
    radius = np.linalg.norm(r, axis=1)
    if np.any(radius < 6.0e6) or np.any(radius > 5.0e7):
        raise ValueError(f"positions must be geocentric in metres (6000 km < |r| < 50000 km); got |r| from "
                         f"{radius.min():.0f} to {radius.max():.0f} m")
    cols = {"time_tai_ns": t, **{c: r[:, i] for i, c in enumerate("xyz")},
            **{c: v[:, i] for i, c in enumerate(("vx", "vy", "vz"))}}
    return ParsedReference(columns=cols, start_tai_ns=int(t[0]), end_tai_ns=int(t[-1]),
                           details={"frame": frame, "earth_fixed": bool(earth_fixed), "source": source,
                                    "n_states": int(t.size)})


def parse_reference_orbit(raw: bytes) -> ParsedReference:
    """CCSDS OEM (first keyword CCSDS_OEM_VERS) or CSV time,x,y,z,vx,vy,vz; ValueError with the reason."""
    head = raw.lstrip()[:64].upper()
    if head.startswith(b"CCSDS_OEM_VERS"):
        return _from_oem(raw)
    return _from_csv(raw)


KINDS = {
    "rinex_nav": ReferenceKind(
        "rinex_nav", parse_rinex_nav_reference,
        "GNSS broadcast ephemerides, RINEX 2 (GPS/GLONASS) or 3 (mixed) navigation file: positions of the "
        "navigation satellites for the antenna axis of 002 (eqs. 5-7)"),
    "reference_orbit": ReferenceKind(
        "reference_orbit", parse_reference_orbit,
        "reference orbit for the energy-integral screening of 002 eq. 15: CCSDS OEM or CSV "
        "time,x,y,z,vx,vy,vz (ISO UTC, m, m/s; '# frame: ITRF' or an inertial frame)"),
}
