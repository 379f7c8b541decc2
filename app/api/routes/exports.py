"""Exports of stored telemetry in exchange formats: GNSS windows as a CCSDS OEM (KVN).

``GET /api/v1/spacecraft/{name}/export/oem?start=&end=`` writes the stored GNSS states of the window
as an Orbit Ephemeris Message (ODM 3.0 or 2.0): REF_FRAME ITRF as stored (exact), or GCRF/EME2000
converted with the newest uploaded ``eop_finals2000a`` data set overlapping the window (zero EOP if
there is none; a COMMENT line says which). See app/services/exports.py.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Response

from app.api.deps import SessionDep, SettingsDep, StoreDep, Viewer
from app.api.files import download_response
from app.services import exports as service

router = APIRouter(prefix="/api/v1/spacecraft/{name}/export", tags=["exports"])


@router.get("/oem", response_class=Response, responses={200: {"content": {"text/plain": {}}}})
def export_oem(
    name: str, session: SessionDep, store: StoreDep, settings: SettingsDep, who: Viewer,
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
    oem = service.oem(session, store, settings, name, who, service.OemRequest(
        start=start, end=end, time_scale=time_scale, sensor=sensor, frame=frame, time_system=time_system,
        version=version, object_id=object_id))
    return download_response(oem)
