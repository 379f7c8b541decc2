"""Bounds on the shape of JSON values that requests hand to the service (job parameters, templates):
nesting depth, items per list or object, string length. Checked before any model sees the value, so
that a crafted value costs the service no more than its size."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from app.services.errors import Invalid


@dataclass(frozen=True)
class JsonBounds:
    max_depth: int = 6  # {"stage_params": {"gyro_bias_fit": {"subintervals": [2]}}} has depth 4
    max_items: int = 64  # elements of any list, keys of any object
    max_string: int = 1000  # characters of any string or object key


PARAM_BOUNDS = JsonBounds()
"""Job parameters (every job type, its pipeline stages, schedule templates)."""


def check_json_shape(value: Any, where: str, bounds: JsonBounds = PARAM_BOUNDS) -> None:
    """Invalid naming the first place where ``value`` exceeds ``bounds`` (iterative: no recursion)."""
    stack: list[tuple[Any, str, int]] = [(value, where, 0)]
    while stack:
        v, path, depth = stack.pop()
        if isinstance(v, str):
            if len(v) > bounds.max_string:
                raise Invalid(f"{path}: string of {len(v)} characters; at most {bounds.max_string}")
            continue
        if not isinstance(v, (dict, list, tuple)):
            continue
        if depth >= bounds.max_depth:
            raise Invalid(f"{path}: nested deeper than {bounds.max_depth} levels")
        if len(v) > bounds.max_items:
            kind = "object of" if isinstance(v, dict) else "list of"
            raise Invalid(f"{path}: {kind} {len(v)} items; at most {bounds.max_items}")
        if isinstance(v, dict):
            for k, item in v.items():
                if isinstance(k, str) and len(k) > bounds.max_string:
                    raise Invalid(f"{path}: key of {len(k)} characters; at most {bounds.max_string}")
                stack.append((item, f"{path}.{k}", depth + 1))
        else:
            stack.extend((item, f"{path}[{i}]", depth + 1) for i, item in enumerate(v))
