"""Software version reported by /healthz and in every report."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("attitude-telemetry")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0+unknown"
