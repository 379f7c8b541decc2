"""The star-tracker-against-gyro plausibility check (processing.star_tracker.plausibility) for the job types
that take both: every head checked, its findings under ``plausibility`` in the summary and its warnings
(``quaternion_convention``, ``implausible_input``, ``time_offset``) among the job's.

gyro_bias_fit runs the check itself (it also corrects the gyro times on request); star_tracker_accuracy,
alignment_calibration and definitive_attitude call :func:`check_heads` so that the same inputs give the
same findings whichever job reads them.

Both go through :func:`checked`, which keeps the last few results keyed by a digest of every input (the
arrays' bytes, dtypes and shapes, and the parameters): a pipeline whose stages check the same tracker against
the same gyro (star_tracker_accuracy, then gyro_bias_fit, in ``reconstruction``) runs the check once (0.7-0.8 s
CPU on a 24 h day of 10 Hz gyro data, against ~0.03 s for the digest), also when the two run side by side:
a caller of a check that another thread is computing waits for its result. Each caller gets its own copy.
"""

from __future__ import annotations

import copy
import hashlib
import threading
from collections import OrderedDict
from collections.abc import Sequence
from concurrent.futures import Future
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.star_tracker.multi_head import HeadSeries
from processing.star_tracker.plausibility import PlausibilityError, PlausibilityResult, check_star_tracker_gyro
from processing.tasks import ResultWarning

CHECK_CACHE_SIZE = 4
"""Results of :func:`checked` kept per process (each a few kB: no arrays of the samples' length)."""

_cache: OrderedDict[str, PlausibilityResult] = OrderedDict()
_cache_lock = threading.Lock()
_running: dict[str, Future[PlausibilityResult]] = {}
"""Checks being computed, by key: a concurrent caller of the same check waits for it instead of computing it
again (the branches of ``reconstruction`` run side by side)."""


def _digest(arrays: Sequence[ArrayLike], params: Sequence[object]) -> str:
    h = hashlib.blake2b(digest_size=20)
    for x in arrays:
        a = np.ascontiguousarray(x)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.data if a.dtype.kind != "O" else repr(a.tolist()).encode())
    h.update(repr(tuple(params)).encode())
    return h.hexdigest()


def checked(t_st_ns: ArrayLike, q_IS: ArrayLike, q_BS: ArrayLike, t_gyro_ns: ArrayLike, w_G: ArrayLike,
            q_BG: ArrayLike, *, sensor: str, max_time_offset_s: float = 1.0) -> PlausibilityResult:
    """:func:`check_star_tracker_gyro` of these inputs, computed once per process for equal inputs (module
    docstring); a deep copy of the kept result. PlausibilityError propagates (and nothing is kept)."""
    key = _digest((t_st_ns, q_IS, q_BS, t_gyro_ns, w_G, q_BG), (sensor, float(max_time_offset_s)))
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return copy.deepcopy(hit)
        running = _running.get(key)
        owner = running is None
        if owner:
            running = _running[key] = Future()
    assert running is not None
    if not owner:  # the same check is being computed by a concurrent stage: its result (or its error)
        return copy.deepcopy(running.result())
    try:
        hit = check_star_tracker_gyro(t_st_ns, q_IS, q_BS, t_gyro_ns, w_G, q_BG, sensor=sensor,
                                      max_time_offset_s=max_time_offset_s)
    except BaseException as exc:
        with _cache_lock:
            del _running[key]
        running.set_exception(exc)
        raise
    with _cache_lock:
        _cache[key] = hit
        while len(_cache) > CHECK_CACHE_SIZE:
            _cache.popitem(last=False)
        del _running[key]
    running.set_result(hit)
    return copy.deepcopy(hit)


def midpoint_rates(t_nodes_ns: NDArray[np.int64], da_G: NDArray[np.float64]) -> tuple[NDArray[np.int64],
                                                                                       NDArray[np.float64]]:
    """Mean rates over consecutive gyro steps at their midpoints: t (M,) int64, w_G (M, 3) rad/s, from node
    times (M+1,) and the angle increments (M, 3) between them (what the check takes for increments)."""
    t = np.asarray(t_nodes_ns, dtype=np.int64)
    dt_s = np.diff(t).astype(np.float64) / 1e9
    return t[:-1] + np.diff(t) // 2, np.asarray(da_G, dtype=np.float64) / dt_s[:, None]


def check_heads(heads: Sequence[HeadSeries], t_gyro_ns: NDArray[np.int64], w_G: NDArray[np.float64],
                q_BG: NDArray[np.float64], notes: list[str],
                max_time_offset_s: float = 1.0) -> tuple[dict[str, Any], list[ResultWarning]]:
    """({head: its plausibility summary, or {"checked": False, "reason": ...}}, the warnings of every head).

    A head that cannot be checked (too few samples within the gyro span) gets a note, not a warning."""
    summary: dict[str, Any] = {}
    warnings: list[ResultWarning] = []
    for h in heads:
        try:
            res = checked(h.time_tai_ns, h.q_IS, h.q_BS, t_gyro_ns, w_G, q_BG, sensor=h.name,
                          max_time_offset_s=max_time_offset_s)
        except PlausibilityError as exc:
            summary[h.name] = {"checked": False, "reason": str(exc)}
            notes.append(f"{h.name}: star tracker not checked against the gyro: {exc}")
            continue
        summary[h.name] = {"checked": True, **res.summary()}
        warnings.extend(res.warnings)
    return summary, warnings
