"""The run form's parameter fields, generated from each job type's parameter model (its JSON schema).

One typed input per parameter: a select for choices and booleans, a number input with the model's
bounds, a text input for strings, and a JSON text input for lists and objects; each with its default
and the model's description as help. Submitted fields are read back with the same types; the JSON
text area of the form, when given, overrides them key by key (the page's script keeps both in step).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

PREFIX = "p."


@dataclass(frozen=True)
class Field:
    name: str
    kind: str  # select | number | integer | text | mixed (a word or a number) | json
    default: Any
    required: bool
    help: str
    choices: tuple[str, ...] = ()
    minimum: float | None = None
    maximum: float | None = None
    nullable: bool = False

    def input_name(self, job_type: str) -> str:
        return f"{PREFIX}{job_type}.{self.name}"

    @property
    def default_text(self) -> str:
        if self.default is None:
            return ""
        if isinstance(self.default, bool):
            return str(self.default).lower()
        if isinstance(self.default, (list, dict)):
            return json.dumps(self.default)
        return str(self.default)


def _variants(prop: Mapping[str, Any]) -> tuple[list[Mapping[str, Any]], bool]:
    options = list(prop.get("anyOf") or [prop])
    nullable = any(o.get("type") == "null" for o in options)
    return [o for o in options if o.get("type") != "null"], nullable


def _field(name: str, prop: Mapping[str, Any], required: bool) -> Field:
    variants, nullable = _variants(prop)
    default = prop.get("default")
    help_text = str(prop.get("description") or "")
    if len(variants) == 1:
        v = variants[0]
        kind = v.get("type")
        if "enum" in v:
            return Field(name, "select", default, required, help_text, tuple(str(x) for x in v["enum"]),
                         nullable=nullable)
        if kind == "boolean":
            return Field(name, "select", default, required, help_text, ("true", "false"), nullable=nullable)
        if kind in ("number", "integer"):
            lo = v.get("minimum", v.get("exclusiveMinimum"))
            hi = v.get("maximum", v.get("exclusiveMaximum"))
            return Field(name, kind, default, required, help_text, minimum=lo, maximum=hi, nullable=nullable)
        if kind == "string":
            return Field(name, "text", default, required, help_text, nullable=nullable)
    if all("const" in v or v.get("type") in ("integer", "number", "string") for v in variants) and variants:
        consts = [str(v["const"]) for v in variants if "const" in v]
        hint = f"{' or '.join(consts)} or a number" if consts else ""
        return Field(name, "mixed", default, required, " ".join(x for x in (help_text, hint and f"({hint})") if x),
                     nullable=nullable)
    return Field(name, "json", default, required, help_text + (" (JSON)" if help_text else "JSON"), nullable=nullable)


def fields(model: type[BaseModel]) -> list[Field]:
    """The form fields of a parameter model, in the model's order."""
    schema = model.model_json_schema()
    required = set(schema.get("required", ()))
    return [_field(name, prop, name in required) for name, prop in schema.get("properties", {}).items()]


def _coerce(f: Field, raw: str) -> Any:
    text = raw.strip()
    if f.kind == "select" and f.choices == ("true", "false"):
        return text == "true"
    if f.kind == "integer":
        return int(text)
    if f.kind == "number":
        return float(text)
    if f.kind == "json":
        return json.loads(text)
    if f.kind == "mixed" and text.lstrip("-").replace(".", "", 1).isdigit():  # e.g. harmonics: "auto" or 32
        return int(text) if text.lstrip("-").isdigit() else float(text)
    return text


def read(model: type[BaseModel], job_type: str, form: Mapping[str, Any]) -> tuple[dict[str, Any],
                                                                                  list[dict[str, Any]]]:
    """The parameters typed into the form for ``job_type`` (empty fields left to their defaults) and the
    fields that could not be read as their type."""
    out: dict[str, Any] = {}
    errors: list[dict[str, Any]] = []
    for f in fields(model):
        raw = form.get(f.input_name(job_type))
        if raw is None or str(raw).strip() == "":
            continue
        try:
            out[f.name] = _coerce(f, str(raw))
        except ValueError as exc:
            errors.append({"row": None, "column": f"params.{f.name}", "message": f"expected {f.kind}: {exc}"})
    return out, errors
