""""Did you mean ...?": the closest valid names for a mistyped one (parameters, job types, config keys)."""

from __future__ import annotations

import difflib
import re
import typing
from collections.abc import Iterable, Sequence
from typing import Any

from pydantic import BaseModel, ValidationError


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """" (did you mean 'x'?)" for the closest of ``choices``, or "" when none is close."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=2, cutoff=0.6)
    if not close:
        return ""
    return " (did you mean " + " or ".join(repr(c) for c in close) + "?)"


def _model_at(model: type[BaseModel], loc: Sequence[Any]) -> type[BaseModel] | None:
    """The model class that holds the field at ``loc`` (dict keys and list indices passed over)."""
    current: Any = model
    for part in loc:
        if not (isinstance(current, type) and issubclass(current, BaseModel)):
            return None
        field = current.model_fields.get(str(part))
        if field is None:
            return None
        current = _inner_model(field.annotation)
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


def _inner_model(annotation: Any) -> Any:
    """The first BaseModel class inside an annotation (Optional, list, dict values)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _inner_model(arg)
        if found is not None:
            return found
    return None


def field_errors(exc: ValidationError, model: type[BaseModel], prefix: str = "") -> list[dict[str, Any]]:
    """One ``{row, column, message}`` per invalid field, unknown names and values with suggestions."""
    out = []
    for e in exc.errors():
        loc = list(e["loc"])
        message = e["msg"]
        if e["type"] == "extra_forbidden" and loc:
            holder = _model_at(model, [p for p in loc[:-1] if not isinstance(p, int)])
            if holder is not None:
                message += did_you_mean(str(loc[-1]), holder.model_fields)
        elif e["type"] == "literal_error":
            expected = re.findall(r"'([^']*)'", str((e.get("ctx") or {}).get("expected", "")))
            message += did_you_mean(str(e.get("input")), expected)
        out.append({"row": None, "column": prefix + ".".join(str(p) for p in loc), "message": message})
    return out
