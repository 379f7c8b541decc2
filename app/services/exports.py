"""Exports of stored telemetry in exchange formats: GNSS windows as a CCSDS OEM (KVN).

The stored GNSS states of the window become an Orbit Ephemeris Message (ODM 3.0 or 2.0): REF_FRAME
ITRF as stored (exact), or GCRF/EME2000 converted with the newest uploaded ``eop_finals2000a`` data
set overlapping the window (zero EOP if there is none; a COMMENT line says which). The message
parses back to the same numbers (processing/formats/ccsds_odm.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sqlalchemy.orm import Session

from app.services.access import Principal
from app.services.downloads import Download
from app.services.errors import Invalid, NotFound
from app.services.spacecraft import get_spacecraft
from app.services.times import parse_window
from app.settings import Settings
from processing.formats.ccsds_odm import oem_segment, write_oem
from processing.frames.earth_orientation import EarthOrientation, itrs_to_inertial_state
from processing.frames.eop import EopCoverageError, interpolate_eop
from processing.streams import STREAMS
from storage.parquet_store import ParquetStore
from storage.reference import ReferenceStore, latest_covering
from storage.telemetry import read_window

EOP_KIND = "eop_finals2000a"


@dataclass(frozen=True)
class OemRequest:
    """What to export: the window (ISO 8601 or seconds since 1970 on ``time_scale``) and the message's form."""

    start: str | None = None
    end: str | None = None
    time_scale: str = "utc"
    sensor: str | None = None
    frame: str = "ITRF"
    time_system: str = "UTC"
    version: str = "3.0"
    object_id: str = "UNKNOWN"


def _inertial(session: Session, settings: Settings, frame: str, t: np.ndarray, r: np.ndarray,
              v: np.ndarray, spacecraft_id: int) -> tuple[np.ndarray, np.ndarray, str]:
    """ITRF states to ``frame`` with the newest EOP data set overlapping the window (zero EOP without one)."""
    eop = EarthOrientation()
    dataset = latest_covering(session, EOP_KIND, int(t[0]), int(t[-1]), spacecraft_id=spacecraft_id)
    if dataset is not None:
        columns = ReferenceStore(settings.reference_url).columns(dataset)
        try:
            eop = interpolate_eop(columns, t, source=f"IERS finals2000A data set {dataset.name!r} ({dataset.id})")
        except EopCoverageError as exc:
            raise Invalid(f"the newest EOP data set does not cover the window: {exc}") from None
    r, v = itrs_to_inertial_state(frame, r, v, t, eop)
    return r, v, f"Converted from ITRF with IAU 2006/2000A; Earth orientation: {eop.source}"


def oem(session: Session, store: ParquetStore, settings: Settings, name: str, who: Principal,
        request: OemRequest) -> Download:
    """The GNSS states of the window as a CCSDS OEM; NotFound when the window has none."""
    sc = get_spacecraft(session, name, who)
    t0, t1 = parse_window(request.start, request.end, request.time_scale)
    table = read_window(session, store, sc.id, STREAMS["gnss"], t0, t1, request.sensor)
    if table.num_rows == 0:
        raise NotFound(f"no gnss samples of {name!r} in the window")
    sensors = sorted(set(table.column("sensor").to_pylist()))
    if len(sensors) > 1:
        raise Invalid(f"several GNSS receivers in the window ({', '.join(sensors)}): give sensor=")
    t = table.column("time_tai_ns").to_numpy()
    r = np.stack([table.column(c).to_numpy() for c in ("x", "y", "z")], axis=-1)
    v = np.stack([table.column(c).to_numpy() for c in ("vx", "vy", "vz")], axis=-1)
    comments = [f"GNSS states of spacecraft {name}, receiver {sensors[0]}, exported by the attitude service"]
    if request.frame != "ITRF":
        r, v, how = _inertial(session, settings, request.frame, t, r, v, sc.id)
        comments.append(how)
    segment = oem_segment(t, r, v, object_name=name, object_id=request.object_id, ref_frame=request.frame,
                          time_system=request.time_system, comments=tuple(comments))
    text = write_oem([segment], originator="ATTITUDE-SERVICE", version=request.version)
    return Download(text.encode(), "text/plain", f"{name}_gnss.oem")
