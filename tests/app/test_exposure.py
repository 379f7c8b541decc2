"""The service refuses a non-loopback address until an API key exists."""

from __future__ import annotations

import subprocess
import sys

import pytest

from app.exposure import UnprotectedBind, check_bind, is_loopback
from app.settings import Settings
from storage.db import make_engine, session_factory, upgrade
from storage.keys import create_key


def test_is_loopback():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("[::1]") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("10.1.2.3") and not is_loopback("example.org")


def test_check_bind(tmp_path):
    url = f"sqlite:///{tmp_path / 'c.db'}"
    settings = Settings(data_dir=tmp_path, database_url=url)
    check_bind(settings, "127.0.0.1")
    with pytest.raises(UnprotectedBind, match="refusing to listen on 0.0.0.0"):
        check_bind(settings, "0.0.0.0")
    check_bind(Settings(data_dir=tmp_path, database_url=url, bootstrap_token="t"), "0.0.0.0")
    engine = make_engine(url)
    upgrade(engine)
    with session_factory(engine).begin() as session:
        create_key(session, name="ops", role="viewer")
    engine.dispose()
    check_bind(settings, "0.0.0.0")


def test_cli_refuses(tmp_path):
    env = {"ATTITUDE_DATA_DIR": str(tmp_path), "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, "-m", "app.cli", "serve", "--host", "0.0.0.0", "--port", "1"],
                       env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "ATTITUDE_BOOTSTRAP_TOKEN" in r.stderr
