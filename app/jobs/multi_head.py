"""The multi-head mode of star_tracker_accuracy: per-head, per-axis noise of several star-tracker heads from
their relative attitude (processing.star_tracker.multi_head), in arcseconds at this edge, with its table,
figure and warnings.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from processing.star_tracker.multi_head import (
    HeadSeries,
    MultiHeadAccuracy,
    MultiHeadError,
    MultiHeadSettings,
    analyze_heads,
    multi_head_warnings,
)
from processing.tasks import ResultWarning, TaskError, TaskInputs
from processing.units import ARCSEC_PER_RAD

MAX_TABLE_ROWS = 50_000
"""The inter-head table is decimated (every k-th pair of samples) to at most this many rows per pair."""


@dataclass(frozen=True)
class MultiHeadOutput:
    summary: dict[str, Any]
    tables: dict[str, dict[str, np.ndarray]]
    warnings: list[ResultWarning]


def _list(x: Any, scale: float = ARCSEC_PER_RAD) -> list[Any]:
    """Plain JSON list of x (any shape) times scale, non-finite values as None."""
    a = np.asarray(x, dtype=float)
    if a.ndim > 1:
        return [_list(row, scale) for row in a]
    return [float(v) * scale if np.isfinite(v) else None for v in a]


def head_names(inputs: TaskInputs, requested: Sequence[str]) -> list[str]:
    """The heads to compare: the requested ones, or ["all"] = every head present in the window."""
    present = list(inputs.sensors("star_tracker"))
    names = present if list(requested) == ["all"] else list(requested)
    missing = [n for n in names if n not in present]
    if missing:
        raise TaskError(f"params.heads: no star_tracker samples of {missing} in the window (present: {present})")
    if len(set(names)) < 2:
        raise TaskError(f"params.heads: the multi-head mode needs at least two heads, got {names} "
                        f"(present in the window: {present})")
    return names


def run_multi_head(inputs: TaskInputs, names: Sequence[str], settings: MultiHeadSettings) -> MultiHeadOutput:
    heads = []
    for n in names:
        st = inputs.star_tracker(n)
        keep = np.concatenate([[True], np.diff(st.time_tai_ns) > 0])
        heads.append(HeadSeries(n, st.time_tai_ns[keep], st.q_IS[keep], inputs.spacecraft.star_tracker_mounting(n)))
    try:
        r = analyze_heads(heads, settings)
    except MultiHeadError as exc:
        raise TaskError(str(exc)) from exc
    return MultiHeadOutput(_summary(r, settings), _tables(r), multi_head_warnings(r))


def _summary(r: MultiHeadAccuracy, s: MultiHeadSettings) -> dict[str, Any]:
    per_head = {}
    for i, h in enumerate(r.heads):
        per_head[h] = {"sigma_arcsec": _list(r.sigma_rad[i]), "sigma_sigma_arcsec": _list(r.sigma_sigma_rad[i]),
                       "observable": [bool(v) for v in r.observable[i]],
                       "sigma_range_arcsec": [None if ok else _list(b) for ok, b in
                                              zip(r.observable[i], r.sigma_bounds_rad[i], strict=True)]}
    pairs = []
    for p in r.pairs:
        b = p.boresight_stats()
        pairs.append({"heads": [p.a, p.b], "n_pairs": p.n_pairs, "n_interpolated": p.n_interpolated,
                      "relative_mounting_error_arcsec": _list(p.relative_mounting_error_rad),
                      "inter_boresight_angle_deg": float(np.degrees(b["mean_rad"])),
                      "inter_boresight_angle_configured_deg": float(np.degrees(p.boresight_angle_configured_rad)),
                      "inter_boresight_angle_std_arcsec": b["std_rad"] * ARCSEC_PER_RAD,
                      "inter_boresight_variation_peak_to_peak_arcsec": b["variation_peak_to_peak_rad"] * ARCSEC_PER_RAD,
                      "ljung_box_p": None if not np.isfinite(p.ljung_box_p) else float(p.ljung_box_p)})
    return {"method": "relative attitude of every pair of heads, no motion model; noise diagonal in each "
                      "head's axes, independent between heads" + (", identical heads" if r.identical_heads else ""),
            "heads": per_head, "axes": ["x1", "x2", "x3"], "pairs": pairs, "identical_heads": r.identical_heads,
            "reduced_chi2": r.reduced_chi2, "dof": r.dof, "correlated_residuals": r.correlated,
            "variance_inflation": r.inflation, "max_interpolation_s": s.max_interpolation_s}


def _tables(r: MultiHeadAccuracy) -> dict[str, dict[str, np.ndarray]]:
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("time_tai_ns", "pair", "e1_arcsec", "e2_arcsec", "e3_arcsec",
                                                          "inter_boresight_deg", "inter_boresight_smooth_deg")}
    for p in r.pairs:
        step = max(1, int(np.ceil(p.time_tai_ns.size / MAX_TABLE_ROWS)))
        cols["time_tai_ns"].append(p.time_tai_ns[::step])
        cols["pair"].append(np.full(p.time_tai_ns[::step].size, f"{p.a}-{p.b}", dtype=object))
        for i in range(3):
            cols[f"e{i + 1}_arcsec"].append(p.residual_rad[::step, i] * ARCSEC_PER_RAD)
        cols["inter_boresight_deg"].append(np.degrees(p.boresight_angle_rad[::step]))
        cols["inter_boresight_smooth_deg"].append(np.degrees(p.boresight_angle_smooth_rad[::step]))
    return {"inter_head": {k: np.concatenate(v) for k, v in cols.items()}}


def figure(tables: dict[str, dict[str, np.ndarray]]) -> Any:
    """Inter-boresight angle of every pair against time: samples and the smoothed (thermal/orbital) variation."""
    from matplotlib.figure import Figure

    t = tables["inter_head"]
    pairs = list(dict.fromkeys(t["pair"].tolist()))
    fig = Figure(figsize=(9, 2.6 * len(pairs) + 0.8), label="Inter-boresight angle of each pair of heads")
    axes = np.atleast_1d(fig.subplots(len(pairs), 1, sharex=True))
    t0 = int(np.min(t["time_tai_ns"]))
    for ax, name in zip(axes, pairs, strict=True):
        m = t["pair"] == name
        tm = (t["time_tai_ns"][m] - t0) / 60e9
        mean = float(np.mean(t["inter_boresight_deg"][m]))
        ax.plot(tm, (t["inter_boresight_deg"][m] - mean) * 3600, ".", ms=1.5, color="tab:gray", label="samples")
        ax.plot(tm, (t["inter_boresight_smooth_deg"][m] - mean) * 3600, color="tab:red", lw=1.2,
                label="slow variation")
        ax.set_ylabel("angle - mean [arcsec]")
        ax.set_title(f"{name}: mean {mean:.4f} deg", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since first sample [min]")
    fig.tight_layout()
    return fig
