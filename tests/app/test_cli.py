"""The command line against a real running service: upload with progress, jobs, schedules, errors; and
the local commands (migrate, create-key) still work."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from app.cli import main
from app.client import ApiClient, Client
from app.devserver import free_port, running_server
from tests.app.helpers import CONFIG

DATA = Path(__file__).parents[1] / "data"

TOKEN = "cli-test-admin-token-0123456789"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = tmp_path_factory.mktemp("cli-server")
    env = {"ATTITUDE_DATA_DIR": str(data), "ATTITUDE_DATABASE_URL": f"sqlite:///{data / 'catalog.db'}",
           "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_MAX_JOBS": "2"}
    with running_server(env, log_path=data / "server.log") as url:
        ApiClient(url, TOKEN).post("/api/v1/spacecraft", {"name": "sat1", "config": CONFIG})
        yield url


def cli(capsys, server, *argv: str) -> tuple[int, str, str]:
    code = main([*argv, "--url", server, "--token", TOKEN])
    out, err = capsys.readouterr()
    return code, out, err


def test_upload_shows_progress_and_reports_the_ingest(server, capsys, tmp_path):
    path = tmp_path / "gyro.csv"
    rows = "".join(f"2023-06-01T{h:02d}:{m:02d}:{s:02d}Z,0.00123456789012,0.00223456789012,0.00323456789012\n"
                   for h in range(6) for m in range(60) for s in range(60))
    path.write_text("time,wx,wy,wz\n" + rows)
    assert path.stat().st_size > 1 << 20  # more than one chunk
    code, out, err = cli(capsys, server, "upload", str(path), "--spacecraft", "sat1", "--stream", "gyro")
    assert code == 0, err
    assert "21600 rows, 21600 new, 0 duplicates" in out
    assert "upload gyro.csv [" in err and "100.0%" in err.splitlines()[-1]
    code, out, _ = cli(capsys, server, "upload", str(path), "--spacecraft", "sat1", "--stream", "gyro", "--json",
                       "--quiet")
    assert code == 0 and json.loads(out)["duplicates"] == 21600
    bad = tmp_path / "gyro.txt"
    bad.write_text("x")
    code, _, err = cli(capsys, server, "upload", str(bad), "--spacecraft", "sat1", "--stream", "gyro")
    assert code == 2 and "cannot tell the format" in err


def test_jobs_submit_watch_list(server, capsys):
    code, out, err = cli(capsys, server, "jobs", "submit", "telemetry_coverage", "--spacecraft", "sat1",
                         "--param", "gap_factor=2.5", "--wait")
    assert code == 0, out + err
    assert "succeeded" in out and "/report" in out and "100.0%" in err
    job_id = out.split()[1]
    code, out, _ = cli(capsys, server, "jobs", "submit", "executor_check", "--spacecraft", "sat1",
                       "--params-json", '{"fail": true}', "--wait", "--quiet")
    assert code == 1 and "failed: executor_check was asked to fail" in out
    code, out, _ = cli(capsys, server, "jobs", "submit", "executor_check", "--spacecraft", "sat1")
    assert code == 0 and len(out.strip()) == 32
    code, out, _ = cli(capsys, server, "jobs", "watch", out.strip(), "--quiet")
    assert code == 0 and "succeeded" in out
    code, out, _ = cli(capsys, server, "jobs", "list", "--type", "telemetry_coverage", "--json")
    listed = json.loads(out)
    assert code == 0 and [j["id"] for j in listed] == [job_id] and listed[0]["params"] == {"gap_factor": 2.5}
    code, out, _ = cli(capsys, server, "jobs", "list")
    assert code == 0 and out.count("\n") == 4  # header + 3 jobs
    code, _, err = cli(capsys, server, "jobs", "submit", "no_such_job", "--spacecraft", "sat1")
    assert code == 2 and "422" in err and "unknown job type" in err


def test_schedules_commands(server, capsys):
    code, out, err = cli(capsys, server, "schedules", "create", "nightly", "--cron", "0 2 * * *", "--type",
                         "telemetry_coverage", "--spacecraft", "sat1", "--window-s", "86400")
    assert code == 0, err
    assert "schedule nightly" in out and "0 2 * * * UTC" in out
    code, out, _ = cli(capsys, server, "schedules", "list")
    assert code == 0 and "nightly" in out and "previous 86400 s" in out
    code, out, _ = cli(capsys, server, "schedules", "show", "nightly", "--json")
    assert code == 0 and json.loads(out)["runs"] == []
    schedule_id = json.loads(out)["schedule"]["id"]
    code, out, _ = cli(capsys, server, "schedules", "show", schedule_id[:8])
    assert code == 0 and f"schedule nightly ({schedule_id})" in out
    code, _, err = cli(capsys, server, "schedules", "show", "nightlyy")
    assert code == 2 and "did you mean 'nightly'?" in err
    code, _, err = cli(capsys, server, "schedules", "create", "bad", "--cron", "every day", "--type",
                       "telemetry_coverage", "--spacecraft", "sat1")
    assert code == 2 and "invalid cron" in err
    code, out, _ = cli(capsys, server, "schedules", "delete", "nightly")
    assert code == 0 and "deleted" in out
    code, _, err = cli(capsys, server, "schedules", "show", "nightly")
    assert code == 2 and "404" in err


def test_authentication_and_connection_errors_exit_2(server, capsys):
    assert main(["jobs", "list", "--url", server, "--token", "wrong"]) == 2
    assert "401" in capsys.readouterr().err
    assert main(["jobs", "list", "--url", server, "--token", ""]) == 2
    assert "an API key is needed" in capsys.readouterr().err
    dead = f"http://127.0.0.1:{free_port()}"
    assert main(["spacecraft", "list", "--url", dead, "--token", TOKEN, "--timeout", "5"]) == 2
    assert f"cannot reach the service at {dead}" in capsys.readouterr().err


def test_local_commands_still_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("ATTITUDE_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("ATTITUDE_DATABASE_URL", raising=False)
    assert main(["migrate"]) == 0
    assert "is up to date" in capsys.readouterr().out
    assert main(["create-key", "--name", "ops", "--role", "viewer"]) == 0
    out = capsys.readouterr().out
    assert "created viewer key" in out and len(out.strip().splitlines()[-1]) >= 20


def test_spacecraft_and_configuration_commands(server, capsys, tmp_path):
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"gyro": {"q_BG": [1, 0, 0, 0]}}))
    code, out, err = cli(capsys, server, "spacecraft", "create", "probe-7", "--config", str(cfg))
    assert code == 0, err
    assert "spacecraft probe-7 created (configuration version 1)" in out
    code, out, _ = cli(capsys, server, "spacecraft", "list")
    assert code == 0 and "probe-7" in out and "sat1" in out and "star trackers st1" in out
    code, out, _ = cli(capsys, server, "spacecraft", "config", "get", "probe-7")
    assert code == 0 and json.loads(out)["gyro"] == {"q_BG": [1.0, 0.0, 0.0, 0.0]}
    new = {"star_trackers": {"st9": {"q_BS": [0, 1, 0, 0]}}}
    cfg.write_text(json.dumps(new))
    code, out, err = cli(capsys, server, "spacecraft", "config", "set", "probe-7", str(cfg))
    assert code == 0 and "configuration version 2 stored" in out, err
    saved = tmp_path / "v1.json"
    code, out, _ = cli(capsys, server, "spacecraft", "config", "get", "probe-7", "--version", "1", "-o", str(saved))
    assert code == 0 and json.loads(saved.read_text())["gyro"]["q_BG"] == [1.0, 0.0, 0.0, 0.0]
    code, out, _ = cli(capsys, server, "spacecraft", "show", "probe-7", "--json")
    assert code == 0 and json.loads(out)["config"]["star_trackers"] == {"st9": {"q_BS": [0.0, 1.0, 0.0, 0.0]}}
    # an invalid configuration: every field named; an unknown name: the nearest one
    cfg.write_text(json.dumps({"gyro": {"q_BG": [1, 1, 0, 0]}, "star_trackrs": {}}))
    code, _, err = cli(capsys, server, "spacecraft", "config", "set", "probe-7", str(cfg))
    assert code == 2 and "422" in err and "star_trackrs" in err and "q_BG" in err, err
    code, _, err = cli(capsys, server, "spacecraft", "show", "probe7")
    assert code == 2 and "404" in err and "did you mean 'probe-7'?" in err
    cfg.write_text("{not json")
    code, _, err = cli(capsys, server, "spacecraft", "create", "x", "--config", str(cfg))
    assert code == 2 and "is not JSON" in err


def test_telemetry_get_formats_and_window(server, capsys, tmp_path):
    Client(server, TOKEN).create_spacecraft("tel1", {})
    rows = "".join(f"2023-06-01T00:00:{s:02d}Z,{s},0,1\n" for s in range(20))
    path = tmp_path / "g.csv"
    path.write_text("time,wx,wy,wz\n" + rows)
    assert cli(capsys, server, "upload", str(path), "--spacecraft", "tel1", "--stream", "gyro", "--quiet")[0] == 0
    code, out, _ = cli(capsys, server, "telemetry", "get", "gyro", "--spacecraft", "tel1",
                       "--start", "2023-06-01T00:00:05Z", "--end", "2023-06-01T00:00:09Z")
    assert code == 0 and out.splitlines()[0] == '"time","sensor","wx","wy","wz"' and len(out.splitlines()) == 6
    assert out.splitlines()[1].startswith('"2023-06-01T00:00:05Z"')
    target = tmp_path / "g.parquet"
    code, _, err = cli(capsys, server, "telemetry", "get", "gyro", "--spacecraft", "tel1", "--format", "parquet",
                       "-o", str(target))
    assert code == 0 and "saved" in err
    table = pq.read_table(target)
    assert table.schema.field("time").type == pa.timestamp("ns", tz="UTC")
    assert table.column_names[:2] == ["time", "time_tai_ns"]
    np.testing.assert_array_equal(table["time_tai_ns"].to_numpy() - table["time"].cast(pa.int64()).to_numpy(),
                                  np.full(20, 37_000_000_000))
    # the downloaded Parquet uploads again unchanged (as duplicates)
    code, out, _ = cli(capsys, server, "upload", str(target), "--spacecraft", "tel1", "--stream", "gyro", "--json",
                       "--quiet")
    assert code == 0 and json.loads(out)["duplicates"] == 20
    code, out, _ = cli(capsys, server, "telemetry", "get", "gyro", "--spacecraft", "tel1", "--format", "json",
                       "--time-scale", "tai", "--time-format", "seconds", "--end", "1685577637")
    assert code == 0 and [r["time"] for r in json.loads(out)] == [1685577637.0]
    exact = tmp_path / "g_tai.csv"
    code, _, _ = cli(capsys, server, "telemetry", "get", "gyro", "--spacecraft", "tel1", "--time-format", "tai_ns",
                     "-o", str(exact))
    header, first = exact.read_text().splitlines()[:2]
    assert code == 0 and header == '"time","time_tai_ns","sensor","wx","wy","wz"'
    assert first.startswith('"2023-06-01T00:00:00Z",' + str(table["time_tai_ns"][0].as_py()))
    code, out, _ = cli(capsys, server, "upload", str(exact), "--spacecraft", "tel1", "--stream", "gyro", "--json",
                       "--quiet")
    assert code == 0 and json.loads(out)["duplicates"] == 20
    code, _, err = cli(capsys, server, "telemetry", "get", "gyroo", "--spacecraft", "tel1")
    assert code == 2 and "unknown stream 'gyroo'" in err


def test_upload_lists_every_error(server, capsys, tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("time,wx,wy,wz\n2023-06-02T00:00:00Z,nan,0,0\n2023-06-02T00:00:01Z,0,x,0\n"
                    "2023-06-02T00:00:02Z,0,0,inf\nnot-a-time,0,0,0\n")
    code, out, err = cli(capsys, server, "upload", str(path), "--spacecraft", "sat1", "--stream", "gyro", "--quiet")
    assert code == 2 and "422" in err and out == ""
    lines = sorted(line for line in err.splitlines() if line.startswith("  row "))
    assert [line.split(",")[0] for line in lines] == ["  row 0", "  row 1", "  row 2", "  row 3"], err
    assert "column wy" in lines[1] and "column time" in lines[3]
    code, out, err = cli(capsys, server, "upload", str(path), "--spacecraft", "sat1", "--stream", "gyro", "--quiet",
                         "--json")
    body = json.loads(out)
    assert code == 2 and body["status"] == 422 and body["error"]["error_count"] == 4
    assert sorted(e["row"] for e in body["error"]["errors"]) == [0, 1, 2, 3]
    code, _, err = cli(capsys, server, "upload", str(path), "--spacecraft", "sat", "--stream", "gyro", "--quiet")
    assert code == 2 and "spacecraft 'sat' not found (did you mean 'sat1'?)" in err


def test_jobs_result_report_artifacts_cancel_with_short_ids(server, capsys, tmp_path, monkeypatch):
    client = Client(server, TOKEN)
    client.create_spacecraft("jobs1", {})
    client.upload("jobs1", "gyro", pa.table({"time": [f"2023-07-01T00:00:{s:02d}Z" for s in range(30)],
                                            "wx": np.zeros(30), "wy": np.zeros(30), "wz": np.zeros(30)}))
    code, out, err = cli(capsys, server, "jobs", "submit", "telemetry_coverage", "--spacecraft", "jobs1",
                         "--wait", "--quiet")
    assert code == 0, out + err
    job_id = out.split()[1]
    assert "verdict: none (no specification" in out and "Gaps in the window: 0" in out  # the headline
    short = job_id[:8]
    code, out, _ = cli(capsys, server, "jobs", "result", short, "--json")
    data = json.loads(out)
    assert code == 0 and data["id"] == job_id and data["headline"]["rows"] and "warnings" in data["result"]
    code, out, _ = cli(capsys, server, "jobs", "watch", short, "--quiet")
    assert code == 0 and f"job {job_id} succeeded" in out
    code, out, _ = cli(capsys, server, "jobs", "report", short, "-o", str(tmp_path / "r.pdf"))
    assert code == 0 and (tmp_path / "r.pdf").read_bytes().startswith(b"%PDF")
    code, out, _ = cli(capsys, server, "jobs", "artifacts", short)
    assert code == 0 and "summary.json" in out and "gaps.parquet" in out
    code, out, _ = cli(capsys, server, "jobs", "artifacts", short, "--kind", "table", "--download", str(tmp_path / "a"))
    assert code == 0 and sorted(p.name for p in (tmp_path / "a").iterdir()) == [
        "coverage.csv", "coverage.parquet", "gaps.csv", "gaps.parquet"]
    code, _, err = cli(capsys, server, "jobs", "artifacts", short, "--name", "nope.csv", "--download", str(tmp_path))
    assert code == 2 and "no artifact 'nope.csv'" in err
    real_artifacts = Client.artifacts  # a long table is listed as Parquet only: its CSV is still asked for by name
    monkeypatch.setattr(Client, "artifacts", lambda self, job: [a for a in real_artifacts(self, job)
                                                               if a["name"] != "gaps.csv"])
    code, out, err = cli(capsys, server, "jobs", "artifacts", short, "--name", "gaps.csv", "--download",
                         str(tmp_path / "b"))
    assert code == 0 and [p.name for p in (tmp_path / "b").iterdir()] == ["gaps.csv"], err
    assert (tmp_path / "b" / "gaps.csv").read_bytes() == (tmp_path / "a" / "gaps.csv").read_bytes()
    monkeypatch.setattr(Client, "artifacts", real_artifacts)
    code, out, _ = cli(capsys, server, "jobs", "submit", "executor_check", "--spacecraft", "jobs1", "--params-json",
                       '{"duration_s": 60}')
    long_id = out.strip()
    code, out, err = cli(capsys, server, "jobs", "cancel", long_id[:6])
    assert code == 0 and long_id in out, err
    code, out, _ = cli(capsys, server, "jobs", "watch", long_id[:8], "--quiet")
    assert code == 1 and "cancelled" in out
    code, _, err = cli(capsys, server, "jobs", "result", "zz")
    assert code == 2 and "at least 4" in err
    # an ambiguous prefix: a second job (as the listing would show it) shares the first 8 characters
    real_pages = Client.pages

    def with_twin(self, path, **params):
        for item in real_pages(self, path, **params):
            yield item
            if path == "/api/v1/jobs" and item["id"] == job_id:
                yield {**item, "id": short + "0" * 24}

    monkeypatch.setattr(Client, "pages", with_twin)
    code, _, err = cli(capsys, server, "jobs", "result", short)
    assert code == 2 and f"job id '{short}' is ambiguous: 2 match" in err and job_id in err


def test_reference_upload_and_list(server, capsys):
    code, out, err = cli(capsys, server, "reference", "upload", "eop_finals2000a",
                         str(DATA / "finals2000A_2017-01-01_04.txt"))
    assert code == 0, err
    assert "reference eop_finals2000a" in out and "rows" in out
    code, out, _ = cli(capsys, server, "reference", "list", "--json")
    assert code == 0 and [d["kind"] for d in json.loads(out)] == ["eop_finals2000a"]
    code, _, err = cli(capsys, server, "reference", "upload", "eop", str(DATA / "finals2000A_2017-01-01_04.txt"))
    assert code == 2 and "unknown reference kind 'eop'" in err


def test_cron_errors_name_the_field(server, capsys):
    code, _, err = cli(capsys, server, "schedules", "create", "bad-hour", "--cron", "0 25 * * *", "--type",
                       "telemetry_coverage", "--spacecraft", "sat1")
    assert code == 2 and "hour 25 out of range 0-23" in err and "expected 5 fields" not in err
