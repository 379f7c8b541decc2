"""The notebook client's job calls: submit, wait (a tqdm bar when installed), cancel, results, headline,
warnings, tables as DataFrames, reports and artifacts to files; schedules."""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.parquet as pq

from app.client.ids import ClientBase, _q

if TYPE_CHECKING:
    import pandas as pd


def _progress_bar(total: float, desc: str) -> Any:
    """A tqdm bar when tqdm is installed (notebooks get the widget), else None."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc, unit="%", bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} % {postfix}")


class JobsClient(ClientBase):
    """Jobs (and schedules) of :class:`app.client.Client`."""

    # -- jobs ----------------------------------------------------------------------------------------
    def job_types(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = self.get("/api/v1/jobs/types")
        return out

    def submit(self, job_type: str, spacecraft: str, *, start: str | float | None = None,
               end: str | float | None = None, time_scale: str = "utc", params: Mapping[str, Any] | None = None,
               reference: Mapping[str, str] | None = None, calibration: str | None = None,
               screened: bool | None = None) -> dict[str, Any]:
        """Submit a job; returns ``{id, status, status_url}`` (202). Bad parameters: :class:`ValidationFailed`."""
        body: dict[str, Any] = {"type": job_type, "spacecraft": spacecraft, "time_scale": time_scale,
                                "params": dict(params or {}), "reference": dict(reference or {})}
        for key, value in (("start", start), ("end", end), ("calibration", calibration), ("screened", screened)):
            if value is not None:
                body[key] = value
        out: dict[str, Any] = self.post("/api/v1/jobs", body)
        return out

    def job(self, job_id: str) -> dict[str, Any]:
        out: dict[str, Any] = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}")
        return out

    def jobs(self, *, spacecraft: str | None = None, type: str | None = None, status: str | None = None,
             limit: int | None = None) -> list[dict[str, Any]]:
        """Jobs, newest first (all pages, or the first ``limit``)."""
        filters = {"spacecraft": spacecraft, "type": type, "status": status}
        if limit is not None:
            return self.list_jobs(**filters, limit=limit)
        return list(self.pages("/api/v1/jobs", **filters))

    def wait(self, job_id: str, *, timeout_s: float = 3600.0, poll_s: float = 0.5,
             progress: bool = True) -> dict[str, Any]:
        """Poll a job until it ends; a tqdm progress bar when tqdm is installed and ``progress``."""
        full = self.resolve_job(job_id)
        bar = _progress_bar(100, f"job {full[:8]}") if progress else None
        try:
            def show(job: dict[str, Any]) -> None:
                if bar is not None:
                    bar.n = round(job["progress"] * 100, 1)
                    bar.set_postfix_str(f"{job['status']}: {job['stage']}", refresh=False)
                    bar.refresh()

            return self.wait_for_job(full, timeout_s=timeout_s, poll_s=poll_s, on_progress=show)
        finally:
            if bar is not None:
                bar.close()

    def run(self, job_type: str, spacecraft: str, *, timeout_s: float = 3600.0, progress: bool = True,
            **submit: Any) -> dict[str, Any]:
        """Submit and wait; returns the finished job (``status`` succeeded, failed or cancelled)."""
        return self.wait(self.submit(job_type, spacecraft, **submit)["id"], timeout_s=timeout_s, progress=progress)

    def cancel(self, job_id: str) -> dict[str, Any]:
        out: dict[str, Any] = self.post(f"/api/v1/jobs/{self.resolve_job(job_id)}/cancel")
        return out

    def result(self, job_id: str) -> dict[str, Any] | None:
        """The job's summary (units in the key names; ``warnings`` inside), None before it succeeded."""
        summary: dict[str, Any] | None = self.job(job_id)["result"]
        return summary

    def report_data(self, job_id: str) -> dict[str, Any]:
        """The report as a dict: warnings, headline (verdict, rows), job, window, inputs, ..."""
        out: dict[str, Any] = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}/report", params={"format": "json"})
        return out

    def headline(self, job_id: str) -> pd.DataFrame:
        """The report's headline rows (quantity, component, value, sigma, unit, frame, verdict) as a DataFrame."""
        import pandas as pd

        rows = self.report_data(job_id)["headline"]["rows"]
        columns = ["quantity", "component", "value", "sigma", "unit", "frame", "verdict", "key", "text"]
        return pd.DataFrame(rows, columns=columns if not rows else None)

    def warnings(self, job_id: str) -> list[dict[str, Any]]:
        """The job's warnings ``{code, message, evidence}``."""
        return list((self.result(job_id) or {}).get("warnings", []))

    def artifacts(self, job_id: str) -> list[dict[str, Any]]:
        """The job's artifacts; figures not drawn yet have ``on_request`` true (no size or checksum): downloading
        one draws and stores it on the service."""
        out: list[dict[str, Any]] = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}/artifacts")
        return out

    def artifact_bytes(self, job_id: str, name: str) -> bytes:
        raw: bytes = self.get(f"/api/v1/jobs/{self.resolve_job(job_id)}/artifacts/{_q(name)}")
        return raw if isinstance(raw, bytes) else json.dumps(raw).encode()

    def table(self, job_id: str, name: str) -> pd.DataFrame:
        """One result table (its Parquet artifact) as a DataFrame; beside ``time_tai_ns`` its ``time`` (ISO text
        in the file) becomes ``datetime64[ns, UTC]`` (POSIX: a leap second holds at the next midnight)."""
        stem = name.removesuffix(".parquet")
        table = pq.read_table(io.BytesIO(self.artifact_bytes(job_id, f"{stem}.parquet")))
        if "time_tai_ns" in table.column_names and "time" in table.column_names \
                and not pa.types.is_timestamp(table.schema.field("time").type):
            from processing.time.timescales import tai_ns_to_epoch_ns

            utc = pa.array(tai_ns_to_epoch_ns(table.column("time_tai_ns").to_numpy(), "utc"), pa.timestamp("ns", "UTC"))
            table = table.set_column(table.column_names.index("time"), "time", utc)
        return table.to_pandas()

    def tables(self, job_id: str) -> dict[str, pd.DataFrame]:
        """Every result table of the job, by name, as DataFrames."""
        full = self.resolve_job(job_id)
        names = [a["name"] for a in self.artifacts(full) if a["kind"] == "table" and a["name"].endswith(".parquet")]
        return {n.removesuffix(".parquet"): self.table(full, n) for n in names}

    def download_artifact(self, job_id: str, name: str, path: str | Path | None = None) -> Path:
        """Save an artifact (to ``path``, a directory or file; default: the current directory)."""
        target = Path(path) if path is not None else Path(name)
        if target.is_dir():
            target = target / name
        target.write_bytes(self.artifact_bytes(job_id, name))
        return target

    def download_artifacts(self, job_id: str, directory: str | Path = ".", kind: str | None = None) -> list[Path]:
        """Save every artifact (or those of ``kind``: table, figure, file, summary) into ``directory``."""
        full = self.resolve_job(job_id)
        folder = Path(directory)
        folder.mkdir(parents=True, exist_ok=True)
        return [self.download_artifact(full, a["name"], folder / a["name"])
                for a in self.artifacts(full) if kind is None or a["kind"] == kind]

    def report(self, job_id: str, path: str | Path | None = None, format: str | None = None) -> Path:
        """Save the report (html, pdf or json; from ``path``'s extension unless given) and return its path."""
        full = self.resolve_job(job_id)
        fmt = format or (Path(path).suffix.lstrip(".").lower() if path is not None else "html") or "html"
        if fmt not in ("html", "pdf", "json"):
            raise ValueError(f"report format must be html, pdf or json, got {fmt!r}")
        target = Path(path) if path is not None else Path(f"report_{full[:8]}.{fmt}")
        raw = self.get(f"/api/v1/jobs/{full}/report", params={"format": fmt})
        target.write_bytes(raw if isinstance(raw, bytes) else json.dumps(raw, indent=2).encode())
        return target

    # -- schedules -----------------------------------------------------------------------------------
    def schedules(self) -> list[dict[str, Any]]:
        return self.list_schedules()
