"""Figures on request (issue 24): the cost of the first and the second request of one figure of a spacecraft-day.

Simulates and uploads one spacecraft-day as bench/pipeline_day.py does, runs a default ``reconstruction`` job in
this process (``ATTITUDE_FIGURES=lazy``: it draws no figure), then GETs one figure through the API twice (the first
draws it from the stored artifacts and stores it, the second serves the stored PNG) and builds the HTML report
(which draws and stores the figures not made yet). Printed: wall and CPU seconds of each request.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/figure_request.py [--hours H] [--figure NAME]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from fastapi.testclient import TestClient

sys.path.insert(0, str(Path(__file__).parent))

from pipeline_day import TOKEN, upload  # noqa: E402

from app.jobs import runner  # noqa: E402
from app.main import create_app  # noqa: E402
from app.services import jobs as job_service  # noqa: E402
from app.services.access import Principal  # noqa: E402
from app.settings import Settings  # noqa: E402
from processing.simulate.seed003 import simulate_seed003  # noqa: E402
from processing.time import timescales  # noqa: E402
from storage import jobs as jobstore  # noqa: E402
from storage.db import make_engine, session_factory  # noqa: E402


def timed(label: str, fn):  # type: ignore[no-untyped-def]
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    print(f"{label:<52}wall {time.perf_counter() - w:6.2f} s  CPU {time.process_time() - c:6.2f} s")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--figure", default="star_tracker_accuracy__residuals")
    a = ap.parse_args()
    start = int(timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0])
    sc = simulate_seed003(start_tai_ns=start, duration_s=a.hours * 3600.0, seed=100, st_period_s=1.0,
                          gyro_period_s=0.1, gnss_period_s=1.0)
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(data_dir=Path(tmp) / "data", database_url=f"sqlite:///{tmp}/catalog.db",
                            bootstrap_token=TOKEN, scheduler=False, max_jobs=1)
        upload(settings, sc.streams, sc.config)
        engine = make_engine(settings.database_url)
        sessions = session_factory(engine)
        with sessions() as session:
            body = job_service.JobCreate.model_validate({"type": "reconstruction", "spacecraft": "sat000"})
            job_id = job_service.submit(session, body, Principal(key_id="bench", name="bench", role="admin"),
                                        on_submit=lambda: None).id
        with sessions.begin() as session:
            assert jobstore.claim(session, job_id)
        state = timed(f"job ({a.hours:g} h reconstruction, no figures)", lambda: runner.execute(job_id, settings))
        assert state == "succeeded", state
        engine.dispose()
        with TestClient(create_app(settings)) as client:
            client.headers["Authorization"] = f"Bearer {TOKEN}"
            url = f"/api/v1/jobs/{job_id}/artifacts/{a.figure}.png"
            listed = timed("artifact list", lambda: client.get(f"/api/v1/jobs/{job_id}/artifacts").json())
            print(f"  {sum(x['on_request'] for x in listed)} figures on request")
            first = timed(f"first GET {a.figure}.png (draw, store)", lambda: client.get(url))
            second = timed(f"second GET {a.figure}.png (stored)", lambda: client.get(url))
            assert first.status_code == second.status_code == 200 and first.content == second.content
            print(f"  {len(first.content)} bytes")
            html = timed("HTML report (draws the other figures)", lambda: client.get(f"/api/v1/jobs/{job_id}/report"))
            assert html.status_code == 200
            timed("HTML report again (all stored)", lambda: client.get(f"/api/v1/jobs/{job_id}/report"))


if __name__ == "__main__":
    main()
