"""Uploads decoded, validated and written in batches (issue 24): with ATTITUDE_INGEST_BATCH_ROWS = 100 a
body of a few thousand rows spans many batches, so every property of an upload (all rows stored, all or
nothing up to the last batch, de-duplication and conflicts against the store, order fallback, every
format) is checked across batch boundaries. One service for the module (SQLite), a spacecraft per test."""

from __future__ import annotations

import errno
import io
import itertools
import sqlite3
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient

from app.ingest.batches import parse_body
from app.ingest.errors import UploadError
from app.ingest.validate import UploadOptions, validate
from app.main import create_app
from app.services.telemetry import sensor_policy
from app.settings import Settings
from processing.streams import STREAMS
from tests.app.helpers import ARROW, CSV, PARQUET, make_spacecraft, upload
from tests.conftest import ADMIN_TOKEN

BATCH = 100
N = 2_500  # 25 batches
T0_S = 1_700_000_000  # UTC seconds; 100 s apart: the rows span 3 TAI days
STEP_S = 100
MAX_DAYS = 20
_names = (f"sc{i}" for i in itertools.count())


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[TestClient, Settings]]:
    root = tmp_path_factory.mktemp("streamed")
    settings = Settings(data_dir=root / "data", database_url=f"sqlite:///{root / 'catalog.db'}",
                        bootstrap_token=ADMIN_TOKEN, auth_failures_per_minute=100_000, ingest_batch_rows=BATCH,
                        max_upload_days=MAX_DAYS)
    with TestClient(create_app(settings)) as c:
        c.headers["Authorization"] = f"Bearer {ADMIN_TOKEN}"
        yield c, settings


@pytest.fixture
def sc(service: tuple[TestClient, Settings]) -> str:
    name = next(_names)
    make_spacecraft(service[0], name)
    return name


def gyro(n: int = N, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"t": T0_S + STEP_S * np.arange(n, dtype=np.int64), "wx": rng.normal(0, 1e-3, n),
            "wy": rng.normal(0, 1e-3, n), "wz": rng.normal(0, 1e-3, n)}


def as_csv(g: dict[str, np.ndarray]) -> str:
    return "time,wx,wy,wz\n" + "".join(f"{t},{x!r},{y!r},{z!r}\n" for t, x, y, z in
                                       zip(g["t"].tolist(), g["wx"].tolist(), g["wy"].tolist(), g["wz"].tolist(),
                                           strict=True))


def as_table(g: dict[str, np.ndarray]) -> pa.Table:
    return pa.table({"time": pa.array(g["t"] * 1_000_000_000, pa.timestamp("ns", tz="UTC")),
                     "wx": g["wx"], "wy": g["wy"], "wz": g["wz"]})


def sc_files(settings: Settings, name: str, client: TestClient) -> list[Path]:
    with sqlite3.connect(settings.database_url.removeprefix("sqlite:///")) as db:
        (sc_id,) = db.execute("SELECT id FROM spacecraft WHERE name = ?", (name,)).fetchone()
    root = settings.telemetry_dir / f"sc={sc_id}"
    return sorted(root.rglob("*.parquet")) if root.exists() else []


def stored(client: TestClient, name: str) -> pa.Table:
    r = client.get(f"/api/v1/spacecraft/{name}/telemetry/gyro", params={"format": "parquet"})
    assert r.status_code == 200, r.text
    return pq.read_table(io.BytesIO(r.content))


def assert_stored(client: TestClient, name: str, g: dict[str, np.ndarray]) -> None:
    table = stored(client, name)
    order = np.argsort(g["t"])
    np.testing.assert_array_equal(table.column("time").cast(pa.int64()).to_numpy(), g["t"][order] * 1_000_000_000)
    for c in ("wx", "wy", "wz"):
        np.testing.assert_array_equal(table.column(c).to_numpy(), g[c][order])


def test_a_body_of_many_batches_stores_every_row_in_row_groups_per_batch(service, sc):
    client, settings = service
    g = gyro()
    r = upload(client, "gyro", as_csv(g), sc=sc)
    assert r.status_code == 201, r.text
    assert (r.json()["rows"], r.json()["inserted"], r.json()["duplicates"]) == (N, N, 0)
    assert_stored(client, sc, g)
    files = sc_files(settings, sc, client)
    tai_days = np.unique((g["t"] + 37) // 86_400).size  # TAI = UTC + 37 s since 2017
    assert len(files) == tai_days == 4 and not any(f.name.startswith(".tmp-") for f in files)  # one per TAI day
    assert sum(pq.ParquetFile(f).metadata.num_row_groups for f in files) >= N // BATCH  # written as it came


def test_an_invalid_row_in_the_last_batch_rejects_everything(service, sc):
    client, settings = service
    g = gyro()
    text = as_csv(g).splitlines()
    text[N] = f"{g['t'][-1]},not-a-number,0,0"  # the last data row (line 0 is the header)
    text[1 + 1234] = f"{g['t'][1234]},1,inf,0"  # and one in a middle batch
    r = upload(client, "gyro", "\n".join(text) + "\n", sc=sc)
    assert r.status_code == 422, r.text
    assert {(e["row"], e["column"]) for e in r.json()["errors"]} == {(1234, "wy"), (N - 1, "wx")}
    assert r.json()["error_count"] == 2
    assert sc_files(settings, sc, client) == []  # nothing published, no staged file left
    assert client.get(f"/api/v1/spacecraft/{sc}/ingests").json() == []
    assert stored(client, sc).num_rows == 0


def test_a_duplicate_reupload_stores_nothing_new_and_a_conflict_is_409(service, sc):
    client, settings = service
    g = gyro()
    body = as_table(g)
    buf = io.BytesIO()
    pq.write_table(body, buf, row_group_size=1_000)  # row groups larger than two batches: read batch by batch
    assert upload(client, "gyro", buf.getvalue(), PARQUET, sc=sc).status_code == 201
    files = sc_files(settings, sc, client)
    again = upload(client, "gyro", buf.getvalue(), PARQUET, sc=sc)
    assert again.status_code == 201, again.text
    assert (again.json()["inserted"], again.json()["duplicates"], again.json()["status"]) == (0, N, "duplicate")
    assert sc_files(settings, sc, client) == files
    changed = dict(g, wz=g["wz"].copy())
    changed["wz"][[7, N - 3]] += 1.0  # the first and the last batch differ from the store
    extra = {k: np.concatenate([v, v[-1:] + (STEP_S if k == "t" else 0)]) for k, v in changed.items()}
    r = upload(client, "gyro", as_csv(extra), sc=sc)  # and one new row that must not be stored either
    assert r.status_code == 409, r.text
    assert r.json()["conflict_count"] == 2 and [c["row"] for c in r.json()["conflicts"]] == [7, N - 3]
    assert sc_files(settings, sc, client) == files
    assert len(client.get(f"/api/v1/spacecraft/{sc}/ingests").json()) == 2
    assert_stored(client, sc, g)


def test_times_going_back_across_batches_are_reported_as_for_the_whole_upload(service, sc):
    """Times must increase per sensor (and key) in upload order, so a valid upload always streams; one
    that goes back across a batch boundary is ingested whole, which reports every row as before."""
    client, settings = service
    g = gyro()
    perm = np.random.default_rng(1).permutation(N)
    shuffled = as_csv({k: v[perm] for k, v in g.items()})
    r = upload(client, "gyro", shuffled, sc=sc)
    assert r.status_code == 422, r.text
    with pytest.raises(UploadError) as whole:
        validate(parse_body(shuffled.encode(), "text/csv"), STREAMS["gyro"], sensor_policy(STREAMS["gyro"], {}),
                 UploadOptions())
    assert r.json()["error_count"] == whole.value.total > 1_000
    assert r.json()["errors"] == [e.as_dict() for e in whole.value.errors]
    g2 = gyro(300)
    g2["t"][BATCH] = g2["t"][BATCH - 1]  # the first row of batch 2 repeats the last time of batch 1
    g2["t"][2 * BATCH] = g2["t"][BATCH + 50]  # the first of batch 3 goes back into batch 2
    r = upload(client, "gyro", as_csv(g2), sc=sc)
    assert r.status_code == 422 and [(e["row"], e["message"]) for e in r.json()["errors"]] == [
        (BATCH, "same time as an earlier row of the same sensor"),
        (2 * BATCH, "time goes backwards (times must increase per sensor)")], r.text
    assert sc_files(settings, sc, client) == []


def _panels_stored_and_read_back(client, sc, t, panel, current):  # noqa: ANN001, ANN202
    """Upload panel currents as CSV (every row new) and read the stream back as Parquet."""
    body = "time,panel,current_a\n" + "".join(f"{a},{p},{c!r}\n" for a, p, c in
                                             zip(t.tolist(), panel.tolist(), current.tolist(), strict=True))
    r = upload(client, "panel_currents", body, sc=sc)
    assert r.status_code == 201 and r.json()["inserted"] == t.size, r.text
    return pq.read_table(io.BytesIO(client.get(f"/api/v1/spacecraft/{sc}/telemetry/panel_currents",
                                               params={"format": "parquet"}).content))


def test_key_groups_in_blocks_not_in_time_order_stream(service, sc):
    client, _ = service
    n = 600  # panel 1 at every time, then panel 0 at every time: 6 batches, not sorted by time overall
    t = np.tile(T0_S + np.arange(n // 2), 2)
    panel = np.repeat([1, 0], n // 2)
    current = np.round(np.random.default_rng(4).uniform(0, 1, n), 6)
    back = _panels_stored_and_read_back(client, sc, t, panel, current)
    np.testing.assert_array_equal(back.column("panel").to_numpy(), np.sort(panel))
    np.testing.assert_array_equal(back.column("current_a").to_numpy(), np.concatenate([current[n // 2:],
                                                                                      current[:n // 2]]))


def test_key_groups_interleaved_in_time_stream_across_batches(service, sc):
    client, _ = service
    n = 1_000  # two panels per time: 10 batches, both groups in each
    t = np.repeat(T0_S + np.arange(n // 2), 2)
    panel = np.tile([1, 0], n // 2)
    current = np.round(np.random.default_rng(2).uniform(0, 1, n), 6)
    back = _panels_stored_and_read_back(client, sc, t, panel, current)
    assert back.num_rows == n
    by_panel = {p: current[panel == p] for p in (0, 1)}  # read back by (sensor, panel, time)
    np.testing.assert_array_equal(back.column("current_a").to_numpy(), np.concatenate([by_panel[0], by_panel[1]]))


def _arrow_stream(table: pa.Table) -> bytes:
    sink = pa.BufferOutputStream()
    with ipc.new_stream(sink, table.schema) as w:
        for batch in table.to_batches(max_chunksize=333):  # batches that straddle the ingest batches
            w.write_batch(batch)
    return sink.getvalue().to_pybytes()


def _parquet_small_groups(table: pa.Table) -> bytes:
    buf = io.BytesIO()
    pq.write_table(table, buf, row_group_size=150)  # row groups read whole and sliced
    return buf.getvalue()


def _json(table: pa.Table) -> bytes:
    import json

    g = table.to_pydict()
    records = [{"time": int(t.timestamp()), "wx": x, "wy": y, "wz": z}
               for t, x, y, z in zip(g["time"], g["wx"], g["wy"], g["wz"], strict=True)]
    return json.dumps(records).encode()


@pytest.mark.parametrize("encode, headers", [
    (lambda t: as_csv({"t": t.column("time").cast(pa.int64()).to_numpy() // 1_000_000_000,
                       **{c: t.column(c).to_numpy() for c in ("wx", "wy", "wz")}}).encode(), CSV),
    (_parquet_small_groups, PARQUET), (_arrow_stream, ARROW), (_json, {"Content-Type": "application/json"}),
], ids=["csv", "parquet", "arrow", "json"])
def test_every_format_goes_through_the_batches(service, sc, encode, headers):
    client, settings = service
    g = gyro(1_234, seed=3)
    r = upload(client, "gyro", encode(as_table(g)), headers, sc=sc)
    assert r.status_code == 201 and r.json()["inserted"] == 1_234, r.text
    assert_stored(client, sc, g)
    files = sc_files(settings, sc, client)
    assert sum(pq.ParquetFile(f).metadata.num_row_groups for f in files) >= 1_234 // BATCH
    bad = dict(g, wx=g["wx"].copy())
    bad["wx"][-1] = np.nan  # the last row of the last batch
    later = {k: (v + 100 * N * STEP_S if k == "t" else v) for k, v in bad.items()}
    r = upload(client, "gyro", encode(as_table(later)), headers, sc=sc)
    assert r.status_code == 422 and [e["row"] for e in r.json()["errors"]] == [1_233], r.text
    assert sc_files(settings, sc, client) == files


def test_the_batch_size_is_a_setting() -> None:
    assert Settings.from_env({"ATTITUDE_INGEST_BATCH_ROWS": "5000"}).ingest_batch_rows == 5000


def test_the_day_cap_counts_every_batch_and_nothing_is_written_beyond_it(service, sc):
    client, settings = service
    days = 30  # 10 rows per day: the cap (20 days) is passed in the third batch
    body = "time,wx,wy,wz\n" + "".join(f"{T0_S + 86_400 * d + 60 * i},1,2,3\n" for d in range(days) for i in range(10))
    r = upload(client, "gyro", body, sc=sc)
    assert r.status_code == 413 and f"{days} different days" in r.json()["detail"], r.text
    assert sc_files(settings, sc, client) == []
    assert client.get(f"/api/v1/spacecraft/{sc}/ingests").json() == []


def test_a_write_failure_in_a_later_batch_stores_nothing(service, sc, monkeypatch):
    client, settings = service
    real = pq.ParquetWriter.write_table
    calls = []

    def fails_on_the_fifth(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 5:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(pq.ParquetWriter, "write_table", fails_on_the_fifth)
    r = upload(client, "gyro", as_csv(gyro()), sc=sc)
    assert r.status_code == 507 and "full" in r.json()["detail"], r.text
    assert len(calls) >= 5
    assert sc_files(settings, sc, client) == []  # the staged files of the earlier batches are gone too
    assert client.get(f"/api/v1/spacecraft/{sc}/ingests").json() == []
