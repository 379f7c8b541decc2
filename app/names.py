"""Names of spacecraft, sensors and configuration keys: what the API, the UI and uploads accept."""

from __future__ import annotations

import re

NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
"""For pydantic patterns (whole-string there); in Python use :func:`valid_name` (``$`` lets a final "\\n" through)."""
_NAME_CHARS = re.compile(r"[A-Za-z0-9_.\-]{1,64}")


def valid_name(name: str) -> bool:
    """1-64 letters, digits, ``_ . -``, and not only dots (``.``/``..`` are path segments that browsers and
    proxies rewrite); no control characters, not even a final newline."""
    return _NAME_CHARS.fullmatch(name) is not None and name.strip(".") != ""


def has_control_characters(text: str) -> bool:
    """Whether ``text`` holds a control character (C0, DEL, C1: newlines, tabs, escapes)."""
    return any(ord(c) < 32 or 127 <= ord(c) < 160 for c in text)
