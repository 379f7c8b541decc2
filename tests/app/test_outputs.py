"""Job outputs (app.jobs.outputs): long tables as Parquet only with their CSV made on request, artifacts
bounded per job with the summary saying what was shortened or left out, long figure lines thinned for
display without changing the picture."""

from __future__ import annotations

import io
import json

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from app.jobs import outputs
from processing.tasks import TaskResult
from processing.time import timescales
from storage.jobs import ArtifactStore

T0 = 1_700_000_000 * 10**9


def _table(n: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    return {"time_tai_ns": T0 + np.arange(n, dtype=np.int64) * 10**8, "value": rng.normal(size=n),
            "sensor": np.array(["=st1" if i % 7 == 0 else "st1" for i in range(n)], dtype=object)}


def test_long_table_parquet_only_and_its_csv_on_request(tmp_path, monkeypatch):
    monkeypatch.setattr(outputs, "CSV_STORED_MAX_ROWS", 100)
    monkeypatch.setattr(outputs, "CSV_BATCH_ROWS", 64)  # several batches: the header once
    store = ArtifactStore(tmp_path)
    result = TaskResult(summary={"x": 1}, tables={"short": _table(100), "long": _table(1000)})
    summary = {"x": 1}
    stored = outputs.write_outputs(store, "job1", result, {}, summary)
    names = [a.name for a in stored]
    assert names == ["summary.json", "short.parquet", "short.csv", "long.parquet"]
    assert summary["outputs"]["parquet_only"] == ["long"] and "truncated" not in summary["outputs"]
    assert json.loads((tmp_path / "job1" / "summary.json").read_text())["outputs"] == summary["outputs"]
    assert any("Parquet only" in n and "long" in n for n in result.notes)
    path = tmp_path / "job1" / "long.parquet"
    text = b"".join(outputs.csv_chunks(path))
    buf = io.BytesIO()
    pacsv.write_csv(outputs.csv_safe(pq.read_table(path)), buf)
    assert text == buf.getvalue() and text.count(b'"time"') == 1 and text.count(b"\n") == 1001
    assert b"\"'=st1\"" in text  # formula-like cells stay defused in the converted CSV
    # converted from a stored short table: the same bytes as its stored CSV
    short = tmp_path / "job1" / "short"
    assert b"".join(outputs.csv_chunks(short.with_suffix(".parquet"))) == short.with_suffix(".csv").read_bytes()


@pytest.mark.parametrize("threads", [1, 2])
def test_tables_truncated_and_left_out_within_the_job_budget(tmp_path, monkeypatch, threads):
    """The same decisions whether the tables are encoded one at a time here or side by side."""
    monkeypatch.setattr(outputs, "ENCODE_THREADS", threads)
    monkeypatch.setattr(outputs.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(outputs, "TABLE_MAX_ROWS", 500)
    monkeypatch.setattr(outputs, "JOB_ARTIFACT_MAX_BYTES", 40_000)
    store = ArtifactStore(tmp_path)
    result = TaskResult(summary={}, tables={"a": _table(2000), "b": _table(2000)},
                        files={"big.bin": (b"\0" * 50_000, "application/octet-stream")})
    summary: dict = {}
    stored = outputs.write_outputs(store, "job2", result, {}, summary)
    assert pq.read_metadata(tmp_path / "job2" / "a.parquet").num_rows == 500
    out = summary["outputs"]
    assert out["truncated"] == {"a": {"rows": 2000, "stored_rows": 500}, "b": {"rows": 2000, "stored_rows": 500}}
    assert "big.bin" in out["omitted"] and out["limits"]["job_artifact_max_bytes"] == 40_000
    assert sum(a.size_bytes for a in stored if a.name != "summary.json") <= 40_000
    assert not (tmp_path / "job2" / "big.bin").exists()
    assert any("truncated" in n for n in result.notes) and any("left out" in n for n in result.notes)


def test_table_columns_convert_as_from_python_values():
    """Text, missing text, numbers and flags stored with the types a list of Python values would give."""
    import pyarrow as pa

    cols = {"time_tai_ns": T0 + np.arange(4, dtype=np.int64), "reason": np.array(["", "spike", None, "a;b"], object),
            "n": np.arange(4), "x": np.array([0.5, np.nan, 1.0, 2.0]), "ok": np.array([True, False, True, True])}
    table = outputs.table_to_arrow(cols)
    assert table.column_names == ["time", *cols]
    for name, values in cols.items():
        assert table.column(name).type == pa.array(values.tolist()).type, name
    assert table.column("reason").combine_chunks().equals(pa.array(cols["reason"].tolist()))
    assert table.column("reason").null_count == 1


def test_iso_column_is_the_iso_text():
    t = T0 + np.array([0, 123, 10**8, 86_400 * 10**9], dtype=np.int64)
    assert outputs.iso_column(t).to_pylist() == timescales.tai_ns_to_iso(t).tolist()
    assert outputs.iso_column(np.zeros(0, np.int64)).to_pylist() == []


def _pixels(fig: Figure) -> np.ndarray:
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(np.int16)


@pytest.mark.parametrize("log_x", [False, True])
def test_thin_lines_keeps_the_picture(log_x):
    rng = np.random.default_rng(5)
    n = 200_000
    x = np.linspace(1.0, 1000.0, n)
    y = np.cumsum(rng.normal(size=n)) * 0.01 + rng.normal(size=n)
    y[123_456] = 40.0  # a spike must survive
    y[50_000:52_000] = np.nan  # a gap must stay a gap

    def draw(thin: bool) -> tuple[Figure, np.ndarray]:
        fig = Figure(figsize=(4, 3), dpi=60)
        ax = fig.add_subplot()
        ax.plot(x, y, lw=0.8)
        ax.plot(x[::10], y[::10] + 5, ls="none", marker=".", ms=1)  # 20,000 markers: below the marker bound
        ax.plot(np.cos(np.arange(30_000) * 0.01) * 100 + 500, np.arange(30_000) * 1e-3, lw=0.5)  # unsorted x
        if log_x:
            ax.set_xscale("log")
        if thin:
            outputs.thin_lines(fig)
        return fig, _pixels(fig)

    _, before = draw(False)
    fig, after = draw(True)
    main, markers, unsorted = fig.axes[0].get_lines()
    kept_x, kept_y = main.get_xdata(), main.get_ydata()
    assert len(kept_x) <= outputs.FIGURE_LINE_MAX_POINTS and np.nanmax(kept_y) == 40.0
    assert np.nanmin(kept_y) == np.nanmin(y) and np.any(np.isnan(kept_y))
    assert len(markers.get_xdata()) == 20_000 and len(unsorted.get_xdata()) == 30_000  # left as they were
    differing = np.mean(np.any(np.abs(before - after) > 60, axis=-1))
    assert differing < 0.01, differing


def test_thin_markers_keep_density_and_outliers():
    rng = np.random.default_rng(8)
    n = 100_000
    x = np.arange(n, dtype=np.float64)
    y = rng.normal(size=n)
    y[77_777] = -30.0
    keep = outputs.display_indices(x, y, outputs.FIGURE_MARKERS_MAX_POINTS, connected=False)
    assert keep is not None and keep.size <= 1.6 * outputs.FIGURE_MARKERS_MAX_POINTS and 77_777 in keep
    assert abs(np.std(y[keep]) - 1.0) < 0.1  # still the cloud, not only its envelope
