"""Two service processes sharing one catalog and store: concurrent uploads of one stream store each
sample once, and of two conflicting batches exactly one is stored and the other answers 409.

Before the cross-process stream lock (storage/locks.py), two processes on one SQLite directory both
answered 201 inserted=N to the same batch and stored it twice.
"""

from __future__ import annotations

import io
import json
import threading
import urllib.error
import urllib.request
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from app.devserver import running_server

TOKEN = "concurrent-ingest-token-0123456789"
ROWS = 20_000
pytestmark = pytest.mark.slow


def call(base: str, method: str, path: str, body: bytes | None = None, content_type: str | None = None):
    headers = {"Authorization": f"Bearer {TOKEN}"}
    if content_type:
        headers["Content-Type"] = content_type
    req = urllib.request.Request(base + path, data=body, method=method, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=120) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def gyro_csv(offset_rad_s: float) -> bytes:
    t = pd.Timestamp("2024-03-01T00:00:00Z") + pd.to_timedelta(np.arange(ROWS) * 100, unit="ms")
    frame = pd.DataFrame({"time": t.strftime("%Y-%m-%dT%H:%M:%S.%fZ"), "wx": 1e-3 + offset_rad_s,
                          "wy": np.linspace(0, 1e-3, ROWS), "wz": 0.0})
    return frame.to_csv(index=False).encode()


def post_all(bases: list[str], bodies: list[bytes]) -> list[tuple[int, dict]]:
    """POST each body to a server (round robin) at the same moment; answers in order."""
    barrier = threading.Barrier(len(bodies))
    out: list[tuple[int, dict]] = [(0, {})] * len(bodies)

    def post(i: int) -> None:
        barrier.wait()
        code, raw = call(bases[i % len(bases)], "POST", "/api/v1/spacecraft/sat/telemetry/gyro", bodies[i],
                         "text/csv")
        out[i] = (code, json.loads(raw))

    threads = [threading.Thread(target=post, args=(i,)) for i in range(len(bodies))]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return out


def stored(base: str) -> pd.DataFrame:
    code, raw = call(base, "GET", "/api/v1/spacecraft/sat/telemetry/gyro?format=parquet")
    assert code == 200
    return pq.read_table(io.BytesIO(raw)).to_pandas()


def test_two_processes_store_each_sample_once_and_refuse_conflicts(tmp_path: Path, database_url: str):
    env = {"ATTITUDE_DATA_DIR": str(tmp_path / "data"), "ATTITUDE_DATABASE_URL": database_url,
           "ATTITUDE_BOOTSTRAP_TOKEN": TOKEN, "ATTITUDE_SCHEDULER": "0"}
    with ExitStack() as stack:
        bases = [stack.enter_context(running_server(env, log_path=tmp_path / f"server{i}.log")) for i in range(2)]
        assert call(bases[0], "POST", "/api/v1/spacecraft", json.dumps({"name": "sat", "config": {}}).encode(),
                    "application/json")[0] == 201

        same = post_all(bases, [gyro_csv(0.0)] * 4)
        assert [code for code, _ in same] == [201] * 4, same
        assert sorted(r["inserted"] for _, r in same) == [0, 0, 0, ROWS]
        assert sorted(r["duplicates"] for _, r in same) == [0, ROWS, ROWS, ROWS]
        assert len(stored(bases[1])) == ROWS

        # Conflicting values for the same identities (a later time range): one wins, one is a 409.
        first, second = (gyro_csv(v) for v in (1e-4, 2e-4))
        shift = b"2024-03-01T00:", b"2024-03-02T00:"
        answers = post_all(bases, [first.replace(*shift), second.replace(*shift)])
        codes = sorted(code for code, _ in answers)
        assert codes == [201, 409], answers
        winner = 1e-4 if answers[0][0] == 201 else 2e-4
        table = stored(bases[0])
        assert len(table) == 2 * ROWS
        day2 = table[table["time"] >= "2024-03-02"]
        np.testing.assert_allclose(day2["wx"].to_numpy(), 1e-3 + winner, rtol=0, atol=1e-15)
