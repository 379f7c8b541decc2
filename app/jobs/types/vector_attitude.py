"""Job ``vector_attitude`` (paper 002): attitude from the antenna axis, magnetometer and panel currents.

Thin layer over processing.vector_attitude.determination: screens the inputs (processing.screening.criteria, default
thresholds) unless told not to, builds the vector pairs, picks the algorithm per epoch (002 figure 1)
and reports q_OB with 002's pitch/yaw/roll, the method and loss per epoch and the residuals.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType
from app.reports.headline import Answer
from processing.screening.criteria import ScreeningParams, screen
from processing.star_tracker.orbital_attitude import angle_stats_deg
from processing.tasks import Progress, TaskError, TaskInputs, TaskResult
from processing.units import DEG_PER_RAD, NS_PER_S
from processing.vector_attitude.determination import (
    VECTORS,
    VectorAttitudeError,
    VectorAttitudeParams,
    observations,
    vector_attitude,
)

METHOD_COLORS = {"q_method": "tab:blue", "quest": "tab:cyan", "svd": "tab:purple", "esoq2": "tab:olive",
                 "loosely_coupled": "tab:orange", "none": "tab:red"}


class Weights(BaseModel):
    model_config = ConfigDict(extra="forbid")
    antenna: float = Field(0.0, ge=0)
    magnetometer: float = Field(0.0, ge=0)
    sun: float = Field(0.0, ge=0)


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    method: Literal["auto", "q_method", "quest", "svd", "esoq2", "loosely_coupled"] = Field(
        "auto", description="auto: 002 figure 1 (three vectors: q-method, eq. 9; magnetometer + antenna: loosely "
                            "coupled, eqs. 10-14; other pairs: two-vector q-method)")
    weights: Weights | None = Field(None, description="a_i of eq. 8; default 1/sigma_i^2 from the error model")
    field_model: Literal["igrf", "dipole"] = Field(
        "igrf", description="model field: IGRF-14, or 002's axial dipole (eq. 2; raise field_model_error_nT)")
    magnetometer_noise_nT: float = Field(100.0, ge=0)
    field_model_error_nT: float = Field(150.0, ge=0, description="IGRF-14 error in LEO")
    current_noise_a: float = Field(0.02, ge=0)
    current_model_error_a: float = Field(0.02, ge=0)
    antenna_sigma_deg: float = Field(8.0, gt=0, description="error of the antenna axis from visibility (per axis)")
    antenna_method: Literal["eq7", "cone"] = Field(
        "cone", description="eq7: the paper's least squares; cone: eq. 7 refined by a cone fit (eq. 5)")
    cone_half_angle_deg: float | None = Field(
        None, gt=0, lt=180, description="antenna cone of eq. 5; default 80")
    screen: bool = Field(True, description="reject samples with the data_screening criteria (default thresholds)")


def _stats_deg(x: np.ndarray) -> dict[str, float | None]:
    """Statistics of an angle series [rad -> deg] on the continuous (unwrapped) series: a roll passing
    +-180 deg is one range, never a 360 deg spread (processing.star_tracker.orbital_attitude.angle_stats_deg)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None}
    return dict(angle_stats_deg(x))


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    notes: list[str] = []
    nav_ref = inputs.reference.get("rinex_nav")
    nav = None if nav_ref is None else nav_ref.columns
    if nav is None:
        notes.append("no rinex_nav reference data: no antenna-axis vector (002 eqs. 5-7)")
    vp = VectorAttitudeParams(
        method=params.method, weights=None if params.weights is None else params.weights.model_dump(),
        field_model=params.field_model,
        magnetometer_noise_nT=params.magnetometer_noise_nT, field_model_error_nT=params.field_model_error_nT,
        current_noise_a=params.current_noise_a, current_model_error_a=params.current_model_error_a,
        antenna_sigma_deg=params.antenna_sigma_deg, antenna_method=params.antenna_method,
        cone_half_angle_deg=params.cone_half_angle_deg)
    screening = None
    rejected: dict[str, int] = {}
    if params.screen:
        progress(0.1, "screening")
        screening = screen(inputs.streams, inputs.spacecraft, ScreeningParams(), nav=nav,
                           selected=[s for s in ("gnss", "magnetometer", "panel_currents", "gnss_visibility")
                                     if s in inputs.streams])
        rejected = {s: int(screening.rejected(s).sum()) for s in screening.n_rows}
    progress(0.3, "vector observations")
    try:
        obs = observations(inputs.streams, inputs.spacecraft, vp, nav=nav, screening=screening)
        progress(0.7, "attitude")
        res = vector_attitude(obs, vp)
    except VectorAttitudeError as exc:
        raise TaskError(str(exc)) from None
    methods, counts = np.unique(res.method.astype(str), return_counts=True)
    n = res.time_tai_ns.size
    ok = res.ok
    bound = res.bound_rad()
    residuals = {}
    for j, v in enumerate(VECTORS):
        r = res.residual_rad[:, j]
        r = r[np.isfinite(r)] * DEG_PER_RAD
        residuals[v] = {"n": int(r.size), "rms_deg": float(np.sqrt(np.mean(r**2))) if r.size else None,
                        "p95_deg": float(np.percentile(r, 95)) if r.size else None}
    missing = {v: {str(k): int(c) for k, c in zip(*np.unique(obs.why[:, j].astype(str), return_counts=True),
                                                   strict=True) if k} for j, v in enumerate(VECTORS)}
    summary: dict[str, Any] = {
        "method": params.method,
        "methods_used": {str(m): int(c) for m, c in zip(methods, counts, strict=True)},
        "n_epochs": int(n), "n_attitude": int(ok.sum()), "availability": float(ok.mean()) if n else 0.0,
        "vectors_available": {v: int(obs.available[:, j].sum()) for j, v in enumerate(VECTORS)},
        "vectors_missing_reasons": missing,
        "residuals": residuals,
        "bound99_deg_median": float(np.nanmedian(bound[ok]) * DEG_PER_RAD) if np.any(ok & np.isfinite(bound)) else None,
        "pitch_deg": _stats_deg(res.pitch_rad), "yaw_deg": _stats_deg(res.yaw_rad),
        "roll_deg": _stats_deg(res.roll_rad),
        "screened": params.screen, "rejected_samples": rejected,
        "navigation_data": None if nav_ref is None else nav_ref.name,
        "orbital_frame": "002: Z2 radial, Y2 orbital angular momentum (inertial), X2 = Y2 x Z2",
    }
    table: dict[str, np.ndarray] = {
        "time_tai_ns": res.time_tai_ns, "method": res.method.astype(object),
        **{f"q{i}": res.q_OB[:, i] for i in range(4)},
        "pitch_deg": res.pitch_rad * DEG_PER_RAD, "yaw_deg": res.yaw_rad * DEG_PER_RAD,
        "roll_deg": res.roll_rad * DEG_PER_RAD,
        "loss": res.loss, "bound99_deg": bound * DEG_PER_RAD,
        **{f"residual_{v}_deg": res.residual_rad[:, j] * DEG_PER_RAD for j, v in enumerate(VECTORS)},
        **{f"used_{v}": res.used[:, j] for j, v in enumerate(VECTORS)},
        "reason": res.reason.astype(object),
    }
    progress(0.9, "done")
    return TaskResult(summary=summary, tables={"attitude": table}, notes=notes)


def _continuous_deg(y: np.ndarray) -> np.ndarray:
    """Angles [deg] without the +-180 jumps (unwrapped in time order), the mean kept in (-180, 180]."""
    y = np.asarray(y, dtype=float).copy()
    ok = np.isfinite(y)
    if ok.any():
        y[ok] = np.rad2deg(np.unwrap(np.deg2rad(y[ok])))
        y[ok] -= 360.0 * np.round(np.mean(y[ok]) / 360.0)
    return y


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    tab = result.tables["attitude"]
    t = np.asarray(tab["time_tai_ns"], dtype=np.int64)
    if t.size == 0:
        return {}
    x = (t - t[0]) / NS_PER_S / 60.0
    method = np.asarray(tab["method"]).astype(str)
    fig = Figure(figsize=(10, 8), layout="constrained",
                 label="Attitude of the body in the orbital frame of 002 (pitch, yaw, roll)")
    axes = fig.subplots(4, 1, sharex=True, height_ratios=(1, 1, 1, 0.6))
    for i, name in enumerate(("pitch_deg", "yaw_deg", "roll_deg")):
        ax = axes[i]
        y = _continuous_deg(tab[name])
        for m in np.unique(method):
            sel = method == m
            if m != "none":
                ax.plot(x[sel], y[sel], ".", ms=2, color=METHOD_COLORS.get(m, "k"), label=m)
        ax.set_ylabel(name.replace("_deg", " [deg]"))
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7, markerscale=4, loc="upper right")
    ax = axes[3]
    kinds = ["q_method", "quest", "svd", "esoq2", "loosely_coupled", "none"]
    present = [k for k in kinds if np.any(method == k)]
    for j, k in enumerate(present):
        sel = method == k
        ax.plot(x[sel], np.full(int(sel.sum()), j), "|", color=METHOD_COLORS.get(k, "k"), ms=8)
    ax.set_yticks(range(len(present)), present)
    ax.set_ylim(-0.6, len(present) - 0.4)
    ax.set_ylabel("algorithm\n(002 fig. 1)", fontsize=8)
    ax.set_xlabel("time since the first epoch [min]")
    out = {"attitude": fig}
    fig2 = Figure(figsize=(10, 4), layout="constrained",
                  label="Residuals of the vector observations and the 99 % error bound")
    ax = fig2.add_subplot()
    for v, c in zip(VECTORS, ("tab:green", "tab:blue", "tab:orange"), strict=True):
        y = np.asarray(tab[f"residual_{v}_deg"], dtype=float)
        sel = np.isfinite(y)
        ax.plot(x[sel], y[sel], ".", ms=2, color=c, label=f"{v} residual")
    b = np.asarray(tab["bound99_deg"], dtype=float)
    ax.plot(x, b, "-", lw=0.8, color="k", label="99 % error bound")
    ax.set_yscale("log")
    ax.set_ylabel("[deg]")
    ax.set_xlabel("time since the first epoch [min]")
    ax.legend(fontsize=7, markerscale=4)
    ax.grid(alpha=0.3)
    out["residuals"] = fig2
    return out


def figure_names(summary: Mapping[str, Any], rows: Mapping[str, int]) -> list[str]:
    """The names :func:`figures` gives (none without attitude rows)."""
    return ["attitude", "residuals"] if rows.get("attitude") else []


JOB = JobType(
    name="vector_attitude", title="Attitude from vector observations (002)", paper="002 eqs. 5-14, figure 1",
    params=Params, run=run, streams=("gnss",), optional_streams=("magnetometer", "panel_currents", "gnss_visibility"),
    figures=figures, figure_names=figure_names, reference=("rinex_nav",), applies_calibration="magnetometer",
    description="Attitude q_OB and 002's pitch/yaw/roll per epoch from the GNSS antenna axis (visibility of the "
                "navigation satellites, eqs. 5-7), the magnetometer against IGRF-14 and the sun vector from the "
                "panel currents; strongly coupled Wahba solution (eqs. 8-9) with three vectors, loosely coupled "
                "scheme (eqs. 10-14) with magnetometer + antenna, chosen per epoch (figure 1).",
    headline=(*(Answer(f"{a}_deg.mean", f"{a.capitalize()}, mean over the window", sigma=f"{a}_deg.std",
                       sigma_label="std", frame="body B in the orbital frame O of 002")
                for a in ("pitch", "yaw", "roll")),
              Answer("bound99_deg_median", "99 % attitude error bound (median)", unit="deg"),
              Answer("availability", "Epochs with an attitude", unit="%", scale=100.0)),
)
