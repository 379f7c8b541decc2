"""The Python client against a real running service, as a notebook would use it: create a spacecraft,
upload DataFrames, read them back equal (timestamps included), run a job, get its headline, warnings,
tables, report and artifacts; typed errors with the API's row/column detail; short ids."""

from __future__ import annotations

import json
import sys
import types

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from app.client import (
    AmbiguousId,
    ApiError,
    Client,
    Conflict,
    NotFound,
    ServiceUnreachable,
    Unauthorized,
    ValidationFailed,
)
from app.devserver import free_port, running_server
from processing.time import timescales
from tests.app.helpers import CONFIG

TOKEN = "client-test-admin-token-0123456789"


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    data = tmp_path_factory.mktemp("client-server")
    env = {"ATTITUDE_DATA_DIR": str(data), "ATTITUDE_DATABASE_URL": f"sqlite:///{data / 'catalog.db'}",
           "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_MAX_JOBS": "2", "ATTITUDE_SCHEDULER": "0"}
    with running_server(env, log_path=data / "server.log") as url:
        yield Client(url, TOKEN)


def gyro_frame(n: int = 600, gap: slice = slice(200, 260)) -> pd.DataFrame:
    """1 Hz gyro rates with a one-minute gap; times as tz-aware UTC timestamps."""
    rng = np.random.default_rng(3)
    t = pd.date_range("2023-06-01T00:00:00Z", periods=n, freq="1s", unit="ns")
    keep = np.ones(n, bool)
    keep[gap] = False
    w = rng.normal(0, 1e-4, (n, 3))
    return pd.DataFrame({"time": t[keep], "wx": w[keep, 0], "wy": w[keep, 1], "wz": w[keep, 2]})


def test_notebook_round_trip(client, tmp_path):
    sc = client.create_spacecraft("nb1", CONFIG)
    assert sc["name"] == "nb1" and sc["config_version"] == 1
    assert client.config("nb1")["star_trackers"] == CONFIG["star_trackers"]
    frame = gyro_frame()
    ingest = client.upload("nb1", "gyro", frame)
    assert ingest["rows"] == len(frame) == ingest["inserted"]

    back = client.telemetry("nb1", "gyro")
    assert str(back["time"].dtype) == "datetime64[ns, UTC]"
    assert list(back.columns) == ["time", "time_tai_ns", "sensor", "wx", "wy", "wz"]
    pd.testing.assert_frame_equal(back[["time", "wx", "wy", "wz"]], frame.reset_index(drop=True))
    # time_tai_ns: the same instants, 37 s ahead of UTC in 2023 (independent of the service's conversion)
    expected_tai = frame["time"].astype("int64").to_numpy() + 37_000_000_000
    np.testing.assert_array_equal(back["time_tai_ns"].to_numpy(), expected_tai)
    assert (back["sensor"] == "gyro").all()
    window = client.telemetry("nb1", "gyro", start="2023-06-01T00:01:00Z", end="2023-06-01T00:01:09Z")
    assert len(window) == 10 and window["time"].iloc[0] == pd.Timestamp("2023-06-01T00:01:00Z")
    # the downloaded frame uploads again as duplicates (time and time_tai_ns agree)
    again = client.upload("nb1", "gyro", back)
    assert again["duplicates"] == len(frame) and again["inserted"] == 0

    job = client.run("telemetry_coverage", "nb1", params={"gap_factor": 2.5}, progress=False)
    assert job["status"] == "succeeded", job
    short = job["id"][:8]
    result = client.result(short)
    assert result is not None and result["streams"][0]["n_gaps"] == 1
    assert client.warnings(short) == result["warnings"]
    head = client.headline(short)
    assert {"quantity", "component", "value", "unit", "verdict"} <= set(head.columns) and len(head) >= 1
    tables = client.tables(short)
    gaps = tables["gaps"]
    assert len(gaps) == 1 and gaps["missing"].iloc[0] == 60
    assert str(gaps["time"].dtype) == "datetime64[ns, UTC]" and gaps["time"].iloc[0] == frame["time"].iloc[199]
    assert gaps["time_tai_ns"].iloc[0] == expected_tai[199] and gaps["after_tai_ns"].iloc[0] == expected_tai[200]
    report = client.report(short, tmp_path / "report.html")
    assert report.read_text().lstrip().lower().startswith("<!doctype html")
    data = json.loads(client.report(short, tmp_path / "report.json").read_text())
    assert data["job"]["id"] == job["id"]
    saved = client.download_artifacts(short, tmp_path / "artifacts", kind="table")
    assert sorted(p.name for p in saved) == ["coverage.csv", "coverage.parquet", "gaps.csv", "gaps.parquet"]
    assert client.download_artifact(short, "summary.json", tmp_path).name == "summary.json"


def test_arrow_table_and_tai_times_across_a_leap_second(client):
    client.create_spacecraft("nb2", {})
    # 2016-12-31T23:59:58 .. 2017-01-01T00:00:01 UTC in 0.5 s steps: 23:59:60 is a real second
    t0 = int(timescales.iso_to_tai_ns(["2016-12-31T23:59:58Z"])[0])
    tai = t0 + np.arange(9, dtype=np.int64) * 500_000_000
    table = pa.table({"time_tai_ns": tai, "wx": np.arange(9.0), "wy": np.zeros(9), "wz": np.ones(9)})
    assert client.upload("nb2", "gyro", table)["rows"] == 9
    back = client.telemetry("nb2", "gyro")
    np.testing.assert_array_equal(back["time_tai_ns"].to_numpy(), tai)  # no sample lost or merged
    utc = back["time"]
    assert utc.is_monotonic_increasing  # the POSIX clock holds at midnight during 23:59:60
    assert (utc.iloc[4:7] == pd.Timestamp("2017-01-01T00:00:00Z")).all()
    on_tai = client.telemetry_table("nb2", "gyro", time_scale="tai")
    assert on_tai.schema.field("time").type == pa.timestamp("ns")  # naive reading on TAI
    np.testing.assert_array_equal(on_tai["time"].cast(pa.int64()).to_numpy(), tai)


def test_typed_errors_carry_rows_and_columns(client):
    client.create_spacecraft("nb3", {})
    frame = gyro_frame(20, slice(0, 0))
    frame.loc[3, "wx"] = np.nan
    frame.loc[7, "wy"] = np.inf
    frame = frame.rename(columns={"wz": "wzz"})
    with pytest.raises(ValidationFailed) as info:
        client.upload("nb3", "gyro", frame)
    err = info.value
    assert err.status == 422 and "nothing stored" in err.detail
    found = {(e.row, e.column) for e in err.errors}
    assert {(None, "wzz"), (None, "wz")} <= found, err.errors
    text = err.describe()
    assert "column wzz" in text and "did you mean 'wz'" in text
    # time_tai_ns beside time must name the same instants (here: one row 1 s off, or read on the wrong scale)
    t = pd.date_range("2023-06-01T00:00:00Z", periods=5, freq="1s", unit="ns")
    tai = t.astype("int64").to_numpy() + 37_000_000_000
    tai[2] += 1_000_000_000
    both = pd.DataFrame({"time": t, "time_tai_ns": tai, "wx": 0.0, "wy": 0.0, "wz": 0.0})
    with pytest.raises(ValidationFailed) as info:
        client.upload("nb3", "gyro", both)
    assert [(e.row, e.column) for e in info.value.errors] == [(2, "time")]
    with pytest.raises(ValidationFailed) as info:
        client.upload("nb3", "gyro", both.assign(time_tai_ns=tai - tai[2] + tai[1]).iloc[:2], time_scale="tai")
    assert "time_scale" in info.value.errors[0].message or info.value.errors[0].column == "time"
    with pytest.raises(ValidationFailed, match="integer nanoseconds"):
        client.upload("nb3", "gyro", pa.table({"time_tai_ns": ["x1"], "wx": [0.0], "wy": [0.0], "wz": [0.0]}))
    with pytest.raises(NotFound):
        client.config("no-such-sat")
    with pytest.raises(ValidationFailed) as info:
        client.submit("telemetry_coverage", "nb3", params={"gap_factr": 2})
    assert any("gap_factor" in e.message for e in info.value.errors) or "gap_factor" in str(info.value.detail)
    with pytest.raises(Conflict):
        client.create_spacecraft("nb3", {})
    with pytest.raises(Unauthorized):
        Client(client.base_url, "wrong-token").spacecraft()
    assert issubclass(ValidationFailed, ApiError)
    with pytest.raises(ServiceUnreachable, match=f"127.0.0.1:{(port := free_port())}"):
        Client(f"http://127.0.0.1:{port}", TOKEN, timeout_s=5).spacecraft()
    with pytest.raises(ValueError, match="API key is needed"):
        Client(client.base_url, "")


def test_short_ids_and_cancel(client):
    client.create_spacecraft("nb4", {})
    client.upload("nb4", "gyro", gyro_frame(30, slice(0, 0)))
    ids = [client.submit("executor_check", "nb4", params={"duration_s": 30})["id"] for _ in range(2)]
    cancelled = client.cancel(ids[0][:6])
    assert cancelled["id"] == ids[0] and cancelled["cancel_requested"]
    assert client.wait(ids[0][:8], timeout_s=60, progress=False)["status"] == "cancelled"
    client.cancel(ids[1])
    all_ids = [j["id"] for j in client.jobs()]
    assert set(ids) <= set(all_ids)
    twins = ["abcd" + "0" * 28, "abcd" + "1" * 28, "abce" + "0" * 28]
    with pytest.raises(AmbiguousId, match="'abcd' is ambiguous: 2 match") as info:
        client._resolve("job", "ABCD", lambda: iter(twins))
    assert info.value.candidates == twins[:2]
    assert client._resolve("job", "abcd1", lambda: iter(twins)) == twins[1]
    with pytest.raises(NotFound, match="no job id starts with"):
        client.job("ffffffff" if not any(i.startswith("ffffffff") for i in all_ids) else "00000000")
    with pytest.raises(ValueError, match="at least 4"):
        client.job("ab")


def test_wait_draws_a_tqdm_bar_when_tqdm_is_installed(client, monkeypatch):
    """tqdm is optional: when importable, wait() feeds it the job's progress (0..100 %) and stage."""
    seen: list[tuple[float, str]] = []

    class FakeBar:
        def __init__(self, total, desc, **_):
            assert total == 100 and desc.startswith("job ")
            self.n, self.postfix, self.closed = 0.0, "", False

        def set_postfix_str(self, text, refresh=True):
            self.postfix = text

        def refresh(self):
            seen.append((self.n, self.postfix))

        def close(self):
            seen.append((-1.0, "closed"))

    monkeypatch.setitem(sys.modules, "tqdm.auto", types.SimpleNamespace(tqdm=FakeBar))
    client.create_spacecraft("nb5", {})
    client.upload("nb5", "gyro", gyro_frame(10, slice(0, 0)))
    job = client.run("executor_check", "nb5", params={"duration_s": 1.0}, timeout_s=60)
    assert job["status"] == "succeeded"
    assert seen[-1] == (-1.0, "closed") and seen[-2] == (100.0, "succeeded: done")
    assert [n for n, _ in seen[:-1]] == sorted(n for n, _ in seen[:-1])  # progress never goes back
    assert client.run("executor_check", "nb5", params={"duration_s": 0.1}, progress=False)["status"] == "succeeded"
    assert seen[-1] == (-1.0, "closed") and len([s for s in seen if s[1] == "closed"]) == 1  # no bar when off
