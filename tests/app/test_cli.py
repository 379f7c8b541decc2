"""The command line against a real running service: upload with progress, jobs, schedules, errors; and
the local commands (migrate, create-key) still work."""

from __future__ import annotations

import json

import pytest

from app.cli import main
from app.client import ApiClient
from app.devserver import running_server
from tests.app.helpers import CONFIG

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
    code, _, err = cli(capsys, server, "schedules", "create", "bad", "--cron", "every day", "--type",
                       "telemetry_coverage", "--spacecraft", "sat1")
    assert code == 2 and "invalid cron" in err
    code, out, _ = cli(capsys, server, "schedules", "delete", "nightly")
    assert code == 0 and "deleted" in out
    code, _, err = cli(capsys, server, "schedules", "show", "nightly")
    assert code == 2 and "404" in err


def test_authentication_errors(server, capsys):
    assert main(["jobs", "list", "--url", server, "--token", "wrong"]) == 2
    assert "401" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="API key is needed"):
        main(["jobs", "list", "--url", server, "--token", ""])


def test_local_commands_still_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("ATTITUDE_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("ATTITUDE_DATABASE_URL", raising=False)
    assert main(["migrate"]) == 0
    assert "is up to date" in capsys.readouterr().out
    assert main(["create-key", "--name", "ops", "--role", "viewer"]) == 0
    out = capsys.readouterr().out
    assert "created viewer key" in out and len(out.strip().splitlines()[-1]) >= 20
