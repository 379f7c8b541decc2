"""Exports of stored telemetry in exchange formats: GNSS windows as a CCSDS OEM (KVN).

``GET /api/v1/spacecraft/{name}/export/oem?start=&end=`` writes the stored GNSS states of the window
as an Orbit Ephemeris Message (ODM 3.0 or 2.0): REF_FRAME ITRF as stored (exact), or GCRF/EME2000
converted with the newest uploaded ``eop_finals2000a`` data set overlapping the window (zero EOP if
there is none; a COMMENT line says which). The message parses back to the same numbers
(processing/formats/ccsds_odm.py).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from fastapi import APIRouter, HTTPException, Query, Request, Response

from app.api.deps import SessionDep, StoreDep, Viewer
from app.api.routes.spacecraft import get_spacecraft
from processing.formats.ccsds_odm import oem_segment, write_oem
from processing.frames.earth_orientation import EarthOrientation, itrs_to_inertial_state
from processing.frames.eop import EopCoverageError, interpolate_eop
from processing.streams import STREAMS
from processing.time import timescales
from storage.reference import ReferenceStore, latest_covering
from storage.telemetry import read_window

router = APIRouter(prefix="/api/v1/spacecraft/{name}/export", tags=["exports"])

EOP_KIND = "eop_finals2000a"


def _bound(value: str | None, scale: str, field: str) -> int | None:
    if value is None or value == "":
        return None
    try:
        try:
            seconds = float(value)
        except ValueError:
            return int(timescales.iso_to_tai_ns(np.array([value], dtype=object), scale)[0])
        return int(timescales.seconds_to_tai_ns(np.array([seconds]), scale)[0])
    except timescales.TimeValueError as exc:
        raise HTTPException(422, f"{field}: {exc}") from None


@router.get("/oem", response_class=Response, responses={200: {"content": {"text/plain": {}}}})
def export_oem(
    name: str, request: Request, session: SessionDep, store: StoreDep, who: Viewer,
    start: Annotated[str | None, Query(description="ISO 8601 or seconds since 1970 on time_scale")] = None,
    end: Annotated[str | None, Query(description="inclusive end of the window")] = None,
    time_scale: Annotated[str, Query(pattern="^(utc|tai|gps|tt)$", description="scale of start/end")] = "utc",
    sensor: Annotated[str | None, Query(description="GNSS receiver (default: all samples of the stream)")] = None,
    frame: Annotated[str, Query(pattern="^(ITRF|GCRF|EME2000)$", description="REF_FRAME of the message")] = "ITRF",
    time_system: Annotated[str, Query(pattern="^(UTC|TAI|GPS|TT)$")] = "UTC",
    version: Annotated[str, Query(pattern="^(2\\.0|3\\.0)$", description="CCSDS_OEM_VERS")] = "3.0",
    object_id: Annotated[str, Query(max_length=64, pattern="^[^\\n\\r=]*$")] = "UNKNOWN",
) -> Response:
    """The GNSS states of the window as a CCSDS OEM (KVN); 404 when the window has none."""
    sc = get_spacecraft(session, name, who)
    t0 = _bound(start, time_scale, "start")
    t1 = _bound(end, time_scale, "end")
    if t0 is not None and t1 is not None and t1 < t0:
        raise HTTPException(422, "end is before start")
    table = read_window(session, store, sc.id, STREAMS["gnss"], t0, t1, sensor)
    if table.num_rows == 0:
        raise HTTPException(404, f"no gnss samples of {name!r} in the window")
    sensors = sorted(set(table.column("sensor").to_pylist()))
    if len(sensors) > 1:
        raise HTTPException(422, f"several GNSS receivers in the window ({', '.join(sensors)}): give sensor=")
    t = table.column("time_tai_ns").to_numpy()
    r = np.stack([table.column(c).to_numpy() for c in ("x", "y", "z")], axis=-1)
    v = np.stack([table.column(c).to_numpy() for c in ("vx", "vy", "vz")], axis=-1)
    comments = [f"GNSS states of spacecraft {name}, receiver {sensors[0]}, exported by the attitude service"]
    if frame != "ITRF":
        eop = EarthOrientation()
        dataset = latest_covering(session, EOP_KIND, int(t[0]), int(t[-1]))
        if dataset is not None:
            columns = ReferenceStore(request.app.state.settings.reference_url).columns(dataset)
            try:
                eop = interpolate_eop(columns, t, source=f"IERS finals2000A data set {dataset.name!r} ({dataset.id})")
            except EopCoverageError as exc:
                raise HTTPException(422, f"the newest EOP data set does not cover the window: {exc}") from None
        r, v = itrs_to_inertial_state(frame, r, v, t, eop)
        comments.append(f"Converted from ITRF with IAU 2006/2000A; Earth orientation: {eop.source}")
    segment = oem_segment(t, r, v, object_name=name, object_id=object_id, ref_frame=frame,
                          time_system=time_system, comments=tuple(comments))
    text = write_oem([segment], originator="ATTITUDE-SERVICE", version=version)
    return Response(text.encode(), media_type="text/plain",
                    headers={"Content-Disposition": f'attachment; filename="{name}_gnss.oem"'})
