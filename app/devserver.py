"""Run the real HTTP service in a child process on a free localhost port (demo, benchmarks, tests)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


_SERVING: dict[str, int] = {}


def serving_pid(base: str) -> int:
    """The process id of the server :func:`running_server` started at ``base`` (benchmarks read its memory)."""
    return _SERVING[base]


@contextmanager
def running_server(env: dict[str, str], log_path: Path | None = None,
                   timeout_s: float = 60.0) -> Iterator[str]:
    """Start ``attitude serve`` with ``env`` added to the environment; yield its base URL."""
    port = free_port()
    log = open(log_path, "ab") if log_path else subprocess.DEVNULL  # noqa: SIM115
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
         "--log-level", "warning"],
        env={**os.environ, **env}, stdout=log, stderr=log,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"server exited with code {proc.returncode} during start-up"
                                   + (f"; see {log_path}" if log_path else ""))
            try:
                with urllib.request.urlopen(base + "/healthz", timeout=2) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"server did not answer /healthz within {timeout_s} s")
            time.sleep(0.1)
        _SERVING[base] = proc.pid
        yield base
    finally:
        _SERVING.pop(base, None)
        stop(proc)
        if log_path:
            log.close()  # type: ignore[union-attr]


def stop(proc: subprocess.Popen[bytes], timeout_s: float = 15.0) -> None:
    """Terminate a server process; kill it when it has not ended after timeout_s."""
    proc.terminate()
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
