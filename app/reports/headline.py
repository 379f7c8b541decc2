"""The headline of a report: the job's answers first — quantity, component, value ± 1σ, unit, frame, verdict.

Each job type declares which summary keys are its answers and which are their sigmas
(``JobType.headline``, a tuple of :class:`Answer`); a type that declares none gets :func:`default_answers`
(the quantities its specification judges, then its top-level numbers and 3-vectors with a unit suffix).
Values are shown in engineers' units (rad -> arcsec, rad/s -> deg/h, as in :mod:`app.reports.summary`);
the verdict of each row comes from the specification checks of :mod:`app.reports.specs` that judge it:
PASS, FAIL, UNDETERMINED (a limited quantity the data did not determine) or "" (no limit applies).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from app.reports.specs import Check, lookup
from processing.units import ARCSEC_PER_RAD, DEG_H_PER_RAD_S

MAX_DEFAULT_ANSWERS = 6
SUFFIX_UNITS: tuple[tuple[str, str, float], ...] = (
    ("_rad_s", "deg/h", DEG_H_PER_RAD_S), ("_rad", "arcsec", ARCSEC_PER_RAD), ("_arcsec_s", "arcsec/s", 1.0),
    ("_arcsec", "arcsec", 1.0), ("_deg_s", "deg/s", 1.0), ("_deg_h", "deg/h", 1.0), ("_deg", "deg", 1.0),
    ("_m_s", "m/s", 1.0), ("_m", "m", 1.0), ("_s", "s", 1.0), ("_nT", "nT", 1.0), ("_percent", "%", 1.0),
    ("_ppm", "ppm", 1.0), ("_N_m", "N m", 1.0), ("_a", "A", 1.0),
)
VERDICTS = ("PASS", "FAIL", "UNDETERMINED")


@dataclass(frozen=True)
class Answer:
    """One answer of a job type, read from its summary.

    ``key``: dotted summary key; one ``*`` segment stands for every entry of an object (the entry's name
    becomes the component). ``sigma``: dotted key of its 1σ, of the same shape (``*`` matched alike);
    ``sigma_label`` says what the ± is when it is not a 1σ uncertainty ("std": a spread over the window).
    ``frame`` names the frame of a vector (``{name}`` is filled from the summary's top-level strings).
    ``components``: names, or the summary key that holds them; default x, y, z for 3-vectors.
    ``unit``/``scale``: the display unit; default from the key's suffix. ``judged_by``: the keys of the
    specification checks that judge it (default: the key itself).
    """

    key: str
    label: str = ""
    sigma: str | None = None
    sigma_label: str = "1σ"
    frame: str = ""
    components: tuple[str, ...] | str | None = None
    unit: str | None = None
    scale: float | None = None
    judged_by: tuple[str, ...] = ()


def unit_of(key: str) -> tuple[str, float]:
    """(display unit, factor) from the key's suffix, e.g. ``gyro_bias_rad_s`` -> ("deg/h", 206264.8)."""
    for part in reversed(key.split(".")):
        for suffix, unit, factor in SUFFIX_UNITS:
            if part.endswith(suffix):
                return unit, factor
    return "", 1.0


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _expand(key: str, summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(concrete key, the name a ``*`` matched or "") for every match of ``key`` in ``summary``."""
    if "*" not in key.split("."):
        return [(key, "")]
    head, _, tail = key.partition(".*")
    parent = lookup(summary, head) if head else summary
    if not isinstance(parent, Mapping):
        return []
    return [(f"{head}.{name}{tail}" if head else f"{name}{tail}", str(name)) for name in parent]


def _present(summary: Mapping[str, Any], key: str) -> bool:
    parent, _, last = key.rpartition(".")
    holder = lookup(summary, parent) if parent else summary
    return isinstance(holder, Mapping) and last in holder


def _as_list(value: Any) -> list[Any] | None:
    if value is None or isinstance(value, (str, bool)) or _is_number(value):
        return [value]
    if isinstance(value, list) and value and all(v is None or _is_number(v) or isinstance(v, bool) for v in value):
        return list(value)
    return None


def _components(answer: Answer, summary: Mapping[str, Any], n: int, matched: str) -> list[str]:
    names: Any = answer.components
    if isinstance(names, str):
        names = summary.get(names)
    if isinstance(names, (list, tuple)) and len(names) == n:
        out = [str(x) for x in names]
    else:
        out = ["x", "y", "z"] if n == 3 else [""] if n == 1 else [str(i + 1) for i in range(n)]
    if matched:
        out = [f"{matched} {c}".strip() for c in out]
    return out


def _frame(answer: Answer, summary: Mapping[str, Any]) -> str:
    strings = {k: v for k, v in summary.items() if isinstance(v, str)}
    try:
        return answer.frame.format_map(strings)
    except (KeyError, ValueError, IndexError):
        return answer.frame


def _verdict(judging: Sequence[Check], i: int, n: int, present: bool) -> str:
    results: list[bool | None] = []
    for c in judging:
        if len(c.passed) == n:
            results.append(c.passed[i])
        elif len(c.passed) == 1:  # one judgement for the whole quantity (e.g. a misalignment angle)
            results.append(c.passed[0])
    if not results:
        return "UNDETERMINED" if judging and not present else ""
    if any(r is False for r in results):
        return "FAIL"
    if any(r is None for r in results):
        return "UNDETERMINED"
    return "PASS"


def format_value(value: Any, sigma: Any = None) -> str:
    """``value ± sigma`` rounded to two significant digits of the sigma; 4 significant digits without one."""
    if value is None:
        return "not determined"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return value
    if isinstance(value, int):
        return f"{value:,}"
    if not math.isfinite(value):
        return str(value)
    if _is_number(sigma) and math.isfinite(sigma) and sigma > 0:
        decimals = 1 - math.floor(math.log10(sigma))
        if decimals > 9 or abs(value) >= 1e12:
            return f"{value:.4g} ± {sigma:.2g}"
        if decimals < 0:  # sigma of 100 or more: round both to its two leading digits
            return f"{round(value, decimals):.0f} ± {round(sigma, decimals):.0f}"
        return f"{value:.{decimals}f} ± {sigma:.{decimals}f}"
    return f"{value:.4g}"


def rows(answers: Sequence[Answer], summary: Mapping[str, Any] | None, checks: Sequence[Check]) -> list[dict[str, Any]]:
    """The headline rows of a summary: one per answer and component (answers absent from it are left out)."""
    if not summary:
        return []
    out: list[dict[str, Any]] = []
    for answer in answers:
        for key, matched in _expand(answer.key, summary):
            if not _present(summary, key):
                continue
            values = _as_list(lookup(summary, key))
            if values is None:
                continue
            sigma_key = answer.sigma.replace("*", matched) if answer.sigma and matched else answer.sigma
            sigmas = _as_list(lookup(summary, sigma_key)) if sigma_key else None
            if sigmas is not None and len(sigmas) != len(values):
                sigmas = None
            unit, factor = (answer.unit, answer.scale or 1.0) if answer.unit is not None else unit_of(key)
            judged_by = [k.replace("*", matched) for k in answer.judged_by] or [key]
            judging = [c for c in checks if c.key in judged_by]
            names = _components(answer, summary, len(values), matched)
            for i, v in enumerate(values):
                s: Any = sigmas[i] if sigmas is not None else None
                v_out = v * factor if _is_number(v) and factor != 1.0 else v
                s_out = s * factor if isinstance(s, (int, float)) and factor != 1.0 else s
                out.append({"quantity": answer.label or key, "key": key, "component": names[i], "value": v_out,
                            "sigma": s_out if _is_number(s_out) else None,
                            "sigma_label": answer.sigma_label if _is_number(s_out) else "",
                            "unit": unit, "frame": _frame(answer, summary),
                            "verdict": _verdict(judging, i, len(values), v is not None),
                            "text": format_value(v_out, s_out)})
    return out


def _sigma_key(summary: Mapping[str, Any], key: str) -> str | None:
    for suffix, _, _ in SUFFIX_UNITS:
        if key.endswith(suffix):
            candidate = f"{key[: -len(suffix)]}_sigma{suffix}"
            if candidate in summary:
                return candidate
    for candidate in (f"{key}_sigma", f"sigma_{key}"):
        if candidate in summary:
            return candidate
    return None


def default_answers(summary: Mapping[str, Any] | None, checks: Sequence[Check]) -> tuple[Answer, ...]:
    """For job types that declare no headline: the judged quantities, then top-level numbers and
    3-vectors with a unit suffix (their ``*_sigma*`` entries as sigmas), at most six."""
    if not summary:
        return ()
    out: list[Answer] = [Answer(c.key, c.label) for c in checks]
    seen = {a.key for a in out}
    sigmas = {k for k in (_sigma_key(summary, key) for key in summary) if k}
    for key, value in summary.items():
        if len(out) >= MAX_DEFAULT_ANSWERS:
            break
        if key in seen or key in sigmas or key.endswith("_tai_ns") or not unit_of(key)[0]:
            continue
        if _is_number(value) or (isinstance(value, list) and len(value) == 3
                                 and all(v is None or _is_number(v) for v in value)):
            out.append(Answer(key, key, sigma=_sigma_key(summary, key)))
    return tuple(out)


def overall(headline_rows: Sequence[Mapping[str, Any]]) -> str:
    """'fail' / 'undetermined' / 'pass' over the rows' verdicts; 'none' when no row was judged."""
    verdicts = {r["verdict"] for r in headline_rows}
    if "FAIL" in verdicts:
        return "fail"
    if "UNDETERMINED" in verdicts:
        return "undetermined"
    return "pass" if "PASS" in verdicts else "none"
