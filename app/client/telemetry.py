"""The notebook client's spacecraft, configuration, telemetry and reference-data calls (DataFrames and
Arrow tables in and out)."""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.parquet as pq

from app.client.ids import ClientBase, _q
from app.client.transport import PARQUET_TYPE

if TYPE_CHECKING:
    import pandas as pd


def to_arrow(data: Any) -> pa.Table:
    """A pandas DataFrame (a DatetimeIndex becomes the ``time`` column) or an Arrow table, as an Arrow table."""
    if isinstance(data, pa.Table):
        return data
    import pandas as pd

    if isinstance(data, pd.DataFrame):
        frame = data
        if isinstance(frame.index, pd.DatetimeIndex):
            frame = frame.rename_axis(frame.index.name or "time").reset_index()
        return pa.Table.from_pandas(frame, preserve_index=False)
    raise TypeError(f"expected a pandas DataFrame, a pyarrow Table or a file path, got {type(data).__name__}")


class TelemetryClient(ClientBase):
    """Spacecraft and their configuration, telemetry upload and read-back, ingests, reference data."""

    # -- spacecraft ----------------------------------------------------------------------------------
    def spacecraft(self) -> list[dict[str, Any]]:
        """Every spacecraft the key may see, with its latest configuration."""
        out: list[dict[str, Any]] = self.get("/api/v1/spacecraft")
        return out

    def spacecraft_info(self, name: str, version: int | None = None) -> dict[str, Any]:
        out: dict[str, Any] = self.get(f"/api/v1/spacecraft/{_q(name)}", params={"version": version})
        return out

    def create_spacecraft(self, name: str, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
        out: dict[str, Any] = self.post("/api/v1/spacecraft", {"name": name, "config": dict(config or {})})
        return out

    def config(self, name: str, version: int | None = None) -> dict[str, Any]:
        """The configuration (latest, or ``version``) as a dict."""
        config: dict[str, Any] = self.spacecraft_info(name, version)["config"]
        return config

    def set_config(self, name: str, config: Mapping[str, Any]) -> dict[str, Any]:
        """Store a new configuration version; returns the spacecraft with ``config_version``."""
        out: dict[str, Any] = self.request("PUT", f"/api/v1/spacecraft/{_q(name)}/config", json_body=dict(config))[1]
        return out

    def calibrations(self, name: str, kind: str | None = None) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get(f"/api/v1/spacecraft/{_q(name)}/calibrations", params={"kind": kind})
        return out

    # -- telemetry -----------------------------------------------------------------------------------
    def upload(self, spacecraft: str, stream: str, data: Any, *, time_scale: str = "utc", sensor: str | None = None,
               quaternion_direction: str | None = None, filename: str | None = None,
               format: str | None = None) -> dict[str, Any]:
        """Upload a DataFrame, an Arrow table or a file (path) to ``stream``; returns the ingest record.

        Times: a ``time`` column (timestamps; tz-aware ones are UTC and need ``time_scale="utc"``; ISO
        strings; seconds since 1970 on ``time_scale``) and/or ``time_tai_ns`` (exact, integer TAI ns).
        All or nothing: a :class:`ValidationFailed` lists every bad row and column.
        """
        params: dict[str, Any] = {"time_scale": time_scale, "sensor": sensor,
                                  "quaternion_direction": quaternion_direction, "format": format}
        if isinstance(data, (str, os.PathLike)):
            out: dict[str, Any] = self.upload_file(spacecraft, stream, data, filename=filename, **params)
            return out
        buf = io.BytesIO()
        pq.write_table(to_arrow(data), buf)
        params["filename"] = filename
        out = self.post(f"/api/v1/spacecraft/{_q(spacecraft)}/telemetry/{_q(stream)}", body=buf.getvalue(),
                        content_type=PARQUET_TYPE, params=params)
        return out

    def telemetry_table(self, spacecraft: str, stream: str, start: str | float | None = None,
                        end: str | float | None = None, *, sensor: str | None = None,
                        time_scale: str = "utc") -> pa.Table:
        """Stored samples in [start, end] as an Arrow table: ``time`` (timestamp ns; UTC tz-aware on the UTC
        scale, naive readings on tai/gps/tt), ``time_tai_ns`` (exact), ``sensor`` and the stream's columns."""
        raw = self.get(f"/api/v1/spacecraft/{_q(spacecraft)}/telemetry/{_q(stream)}", params={
            "start": start, "end": end, "sensor": sensor, "time_scale": time_scale, "format": "parquet"})
        return pq.read_table(io.BytesIO(raw))

    def telemetry(self, spacecraft: str, stream: str, start: str | float | None = None,
                  end: str | float | None = None, *, sensor: str | None = None,
                  time_scale: str = "utc") -> pd.DataFrame:
        """Stored samples as a DataFrame (``time`` is ``datetime64[ns, UTC]`` on the UTC scale)."""
        return self.telemetry_table(spacecraft, stream, start, end, sensor=sensor, time_scale=time_scale).to_pandas()

    def ingests(self, spacecraft: str, stream: str | None = None) -> list[dict[str, Any]]:
        return list(self.pages(f"/api/v1/spacecraft/{_q(spacecraft)}/ingests", stream=stream))

    def retract(self, spacecraft: str, ingest_id: str, reason: str) -> dict[str, Any]:
        full = self.resolve_ingest(spacecraft, ingest_id)
        out: dict[str, Any] = self.delete(f"/api/v1/spacecraft/{_q(spacecraft)}/ingests/{full}",
                                          params={"reason": reason})
        return out

    # -- reference data ----------------------------------------------------------------------------
    def reference_kinds(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get("/api/v1/reference/kinds")
        return out

    def upload_reference(self, kind: str, path: str | Path, name: str | None = None) -> dict[str, Any]:
        """Upload a reference file (EOP, RINEX navigation, ...); parsed at once (422 with the reason)."""
        path = Path(path)
        out: dict[str, Any] = self.post(f"/api/v1/reference/{_q(kind)}", body=path.read_bytes(),
                                        content_type="application/octet-stream",
                                        params={"name": name, "filename": path.name})
        return out

    def reference(self, kind: str | None = None) -> list[dict[str, Any]]:
        return list(self.pages("/api/v1/reference", kind=kind))
