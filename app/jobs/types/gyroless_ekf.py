"""Job ``gyroless_ekf`` (paper 004): attitude and rate of a gyroless spacecraft from magnetometer, sun
sensor and GNSS, by the EKF of 004 or a multiplicative EKF, with an optional RTS smoother.

Thin layer over :func:`processing.gyroless.estimation.estimate_gyroless_attitude`: picks the sensors and
their mountings and the inertia from the configuration, converts radians to degrees at the edge,
builds the summary (consistency statistics instead of errors, since the truth is unknown), the
attitude/rate and innovation tables, and figures in the spirit of 004 figs. 3-7.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType, always
from app.reports.headline import Answer
from processing.gyroless.ekf import FilterTuning
from processing.gyroless.estimation import GyrolessError, GyrolessResult, GyrolessSettings, estimate_gyroless_attitude
from processing.star_tracker.orbital_attitude import angle_stats_deg
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import DEG_PER_RAD, NS_PER_S


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    filter: Literal["ekf", "mekf"] = Field("mekf", description="ekf: the 9-state EKF of 004; mekf: multiplicative EKF")
    smoother: bool = Field(True, description="run the Rauch-Tung-Striebel smoother after the filter")
    magnetometer_noise_nT: float = Field(100.0, gt=0, le=1e5, description="magnetometer noise, 1 sigma per axis")
    field_model_error_nT: float = Field(0.0, ge=0, le=1e5,
                                        description="IGRF model error added in quadrature (crustal/external fields)")
    sun_sensor_noise_deg: float = Field(0.5, gt=0, le=30, description="sun-sensor noise, 1 sigma per axis")
    torque_noise_N_m: float | None = Field(
        None, gt=0, le=1.0, description="unmodelled torque, sqrt of its PSD [N m sqrt(s)]; default 4e-6, or 1e-5 "
                                        "with model-error states (estimate_magnetometer_bias, field_error_sigma_nT)")
    disturbance_walk_N_m: float = Field(1e-7, ge=0, le=1.0,
                                        description="random walk of the estimated disturbance [N m / sqrt(s)]")
    initial_angles_deg: tuple[float, float, float] | None = Field(
        None, description="(roll, pitch, yaw) start instead of the two-vector (TRIAD) solution")
    initial_attitude_sigma_deg: float = Field(10.0, gt=0, le=180)
    initial_rate_sigma_rad_s: float = Field(2e-3, gt=0, le=1.0)
    converged_sigma_deg: float = Field(2.0, gt=0, le=90, description="convergence: 1-sigma attitude bound below this")
    estimate_magnetometer_bias: bool = Field(False, description="carry the magnetometer bias (body axes) as 3 "
                                                                "filter states (for an uncalibrated magnetometer)")
    magnetometer_bias_sigma_nT: float = Field(1000.0, gt=0, le=1e5, description="prior 1-sigma of the bias")
    field_error_sigma_nT: float = Field(0.0, ge=0, le=1e5, description="reference-field error in the orbital "
                                        "frame as a first-order Gauss-Markov process, 1-sigma per axis (0: off)")
    field_error_tau_s: float = Field(1800.0, gt=0, le=1e6, description="its correlation time")
    magnetometer_sensor: str | None = Field(None, description="sensor name; default the only one in the data")
    sun_sensor_name: str | None = Field(None, description="sun-sensor name; default the only one in the data")


def _clean(value: Any) -> Any:
    """Plain JSON types: numpy scalars/arrays to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_clean(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def _sensor(inputs: TaskInputs, stream: str, requested: str | None) -> str | None:
    """The requested sensor, or None for the only one in the data (TaskError when there are several)."""
    present = inputs.sensors(stream)
    if requested is None and len(present) > 1:
        raise TaskError(f"several {stream} sensors in the data ({list(present)}); set the sensor parameter")
    return requested


def _intervals(t_ns: np.ndarray, flag: np.ndarray) -> list[dict[str, Any]]:
    """Contiguous runs where flag is True, as {start_tai_ns, end_tai_ns, duration_s}."""
    f = np.concatenate([[False], flag, [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(f) == 1), np.flatnonzero(np.diff(f) == -1) - 1
    return [{"start_tai_ns": int(t_ns[a]), "end_tai_ns": int(t_ns[b]),
             "duration_s": float((t_ns[b] - t_ns[a]) / NS_PER_S)} for a, b in zip(starts, ends, strict=True)]


def _summary(r: GyrolessResult, params: Params) -> dict[str, Any]:
    t = r.time_tai_ns
    ts = (t - t[0]) / NS_PER_S
    conv = r.time_to_converge_s
    after = ts >= (conv if conv is not None else ts[-1] + 1)
    sig = r.attitude_sigma_rad * DEG_PER_RAD
    outage = ~r.sun_used
    ns, wh = r.nis_stats, r.whiteness_stats
    res = r.filtered.residual_rad * DEG_PER_RAD

    def rms(x: np.ndarray) -> float | None:
        x = x[np.isfinite(x)]
        return float(np.sqrt(np.mean(x * x))) if x.size else None

    return _clean({
        "filter": params.filter,
        "smoother": params.smoother,
        "n_steps": int(t.size),
        "step_s": float(np.median(np.diff(ts))) if t.size > 1 else None,
        "start_tai_ns": int(t[0]),
        "end_tai_ns": int(t[-1]),
        "converged": bool(r.converged),
        "time_to_converge_s": conv,
        "nis_mean": ns.mean,
        "nis_dof_mean": ns.mean_dof,
        "nis_mean_bounds_95": list(ns.mean_bounds),
        "nis_mean_in_bounds": ns.mean_in_bounds,
        "nis_fraction_in_95": ns.fraction_in_95,
        "whiteness": {"max_lag": int(wh.rho.shape[1]) if wh.rho.ndim == 2 else 0, "bound": wh.bound,
                      "fraction_outside": wh.fraction_outside, "max_abs_rho": wh.max_abs_rho,
                      "rho": wh.rho},
        "consistency": _consistency(r),
        "process_noise": {"torque_noise_N_m": math.sqrt(r.settings.resolved_tuning().torque_noise_psd_N2_m2_s),
                          "disturbance_walk_N_m": math.sqrt(r.settings.resolved_tuning().disturbance_walk_psd_N2_m2_s)},
        "magnetometer_bias": _bias(r),
        "field_error_O_nT": _field_error(r),
        "innovation_rms_deg": {"magnetometer": rms(res[:, 0]), "sun_sensor": rms(res[:, 1])},
        "roll_deg": angle_stats_deg(r.roll_rad),
        "pitch_deg": angle_stats_deg(r.pitch_rad),
        "yaw_deg": angle_stats_deg(r.yaw_rad),
        "attitude_sigma_deg": {
            "median": np.median(sig, axis=0).tolist(),
            "max_after_convergence": (sig[after].max(axis=0).tolist() if np.any(after) else None),
            "max_in_sun_outage": (sig[outage].max(axis=0).tolist() if np.any(outage) else None),
            "axes": ["x", "y", "z"],
        },
        "rate_sigma_deg_s": {"median": (np.median(r.rate_sigma_rad_s, axis=0) * DEG_PER_RAD).tolist()},
        "disturbance_N_m": {"mean": np.mean(r.tau_d_O_N_m, axis=0).tolist(), "axes": ["x_O", "y_O"]},
        "sun_used_fraction": float(np.mean(r.sun_used)),
        "sun_outages": _intervals(t, outage),
        "counts": r.counts,
        "artifacts": {"attitude": "attitude series (q_OB, roll/pitch/yaw, 1-sigma, rates, disturbance; with the "
                                  "model-error states mag_bias_{x,y,z}_nT in B and field_error_{x,y,z}_nT in O)",
                      "innovations": "per-step NIS and residual angles"},
    })


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    spacecraft = inputs.spacecraft
    if spacecraft.inertia_kg_m2 is None:
        raise TaskError("the spacecraft configuration has no inertia_kg_m2 (needed by the 004 dynamics model)")
    q_BM, q_BS = spacecraft.magnetometer_mounting(), spacecraft.sun_sensor_mounting()
    progress(0.05, "loading telemetry")
    mag = inputs.magnetometer(_sensor(inputs, "magnetometer", params.magnetometer_sensor))
    if not inputs.sensors("sun_sensor"):
        raise TaskError("no sun_sensor samples in the job window: the filter needs both vectors to start")
    sun = inputs.sun_sensor(_sensor(inputs, "sun_sensor", params.sun_sensor_name))
    gnss = inputs.gnss(_sensor(inputs, "gnss", None))
    tq = inputs.magnetorquer(_sensor(inputs, "magnetorquer", None)) if inputs.sensors("magnetorquer") else None
    settings = GyrolessSettings(
        filter=params.filter, smoother=params.smoother, magnetometer_noise_nT=params.magnetometer_noise_nT,
        field_model_error_nT=params.field_model_error_nT, sun_sensor_noise_deg=params.sun_sensor_noise_deg,
        initial_angles_deg=params.initial_angles_deg, initial_attitude_sigma_deg=params.initial_attitude_sigma_deg,
        initial_rate_sigma_rad_s=params.initial_rate_sigma_rad_s, converged_sigma_deg=params.converged_sigma_deg,
        estimate_magnetometer_bias=params.estimate_magnetometer_bias,
        magnetometer_bias_sigma_nT=params.magnetometer_bias_sigma_nT,
        field_error_sigma_nT=params.field_error_sigma_nT, field_error_tau_s=params.field_error_tau_s,
    )
    torque_noise = params.torque_noise_N_m
    if torque_noise is None:
        torque_noise = math.sqrt(settings.resolved_tuning().torque_noise_psd_N2_m2_s)
    settings = replace(settings, tuning=FilterTuning(torque_noise_psd_N2_m2_s=torque_noise**2,
                                                     disturbance_walk_psd_N2_m2_s=params.disturbance_walk_N_m**2))
    progress(0.2, f"{params.filter} filter" + (" and smoother" if params.smoother else ""))
    try:
        r = estimate_gyroless_attitude(
            mag_time_tai_ns=mag.time_tai_ns, mag_M_nT=mag.b_M_nT, sun_time_tai_ns=sun.time_tai_ns, sun_S=sun.s_S,
            gnss_time_tai_ns=gnss.time_tai_ns, gnss_r_E_m=gnss.r_E_m, gnss_v_E_m_s=gnss.v_E_m_s,
            inertia_kg_m2=spacecraft.inertia_kg_m2,
            torquer_time_tai_ns=None if tq is None else tq.time_tai_ns,
            torquer_mu_B_A_m2=None if tq is None else tq.m_B_A_m2,
            q_BM=q_BM, q_BS=q_BS, settings=settings,
        )
    except (GyrolessError, ValueError) as exc:
        raise TaskError(str(exc)) from exc
    progress(0.9, "summary and tables")
    return TaskResult(summary=_summary(r, params), tables=_tables(r), notes=list(r.notes), warnings=_warnings(r))


BIAS_OBSERVABLE_RATIO = 0.5
"""A bias component is determined when its posterior 1-sigma is below this fraction of the prior."""


def _bias(r: GyrolessResult) -> dict[str, Any] | None:
    """Magnetometer bias in B (the arc's estimate: smoothed at the first step, else filtered at the last)."""
    if "magnetometer_bias_B_nT" not in r.model_errors:
        return None
    v, sig = r.model_errors["magnetometer_bias_B_nT"]
    k = 0 if r.smoothed is not None else -1
    obs = sig[k] < BIAS_OBSERVABLE_RATIO * r.settings.magnetometer_bias_sigma_nT
    return {"value_B_nT": [float(x) if o else None for x, o in zip(v[k], obs, strict=True)],
            "sigma_B_nT": [float(x) if o else None for x, o in zip(sig[k], obs, strict=True)],
            "observable": [bool(o) for o in obs], "prior_sigma_nT": r.settings.magnetometer_bias_sigma_nT,
            "axes": ["x_B", "y_B", "z_B"]}


def _warnings(r: GyrolessResult) -> list[ResultWarning]:
    """filter_inconsistent when the consistency gates fail (processing.gyroless.estimation.filter_consistency);
    not_observable for bias components the arc does not determine."""
    out = []
    b = _bias(r)
    if b is not None and not all(b["observable"]):
        axes = [a for a, o in zip(b["axes"], b["observable"], strict=True) if not o]
        out.append(ResultWarning("not_observable", f"the arc does not determine the magnetometer bias along "
                                 f"{', '.join(axes)} (posterior sigma above {BIAS_OBSERVABLE_RATIO:g} of the prior): "
                                 "reported as null", {"axes": axes, "prior_sigma_nT": b["prior_sigma_nT"]}))
    g = r.consistency
    if g.consistent:
        return out
    return [*out, ResultWarning(
        "filter_inconsistent",
        "the magnetometer/sun-sensor innovations disagree with the filter's covariance ("
        + "; ".join(g.reasons) + "): the attitude sigma does not cover the error. Calibrate the magnetometer "
        "(magnetometer_calibration), estimate its bias (estimate_magnetometer_bias) or model the field error "
        "(field_error_sigma_nT, field_error_tau_s)",
        _consistency(r))]


def _field_error(r: GyrolessResult) -> dict[str, Any] | None:
    if "field_error_O_nT" not in r.model_errors:
        return None
    v, sig = r.model_errors["field_error_O_nT"]
    return {"rms": np.sqrt(np.mean(v**2, axis=0)).tolist(), "sigma_median": np.median(sig, axis=0).tolist(),
            "sigma_nT": r.settings.field_error_sigma_nT, "tau_s": r.settings.field_error_tau_s,
            "axes": ["x_O", "y_O", "z_O"]}


def _consistency(r: GyrolessResult) -> dict[str, Any]:
    g = r.consistency
    return _clean({
        "tested_from_s": g.start_s, "nis_mean": g.nis.mean, "nis_dof": g.nis.mean_dof,
        "nis_bounds_99": list(g.nis_bounds_99), "nis_ok": g.nis_ok, "window_s": g.window_s,
        "n_windows": g.n_windows, "windows_failed": g.windows_failed, "windows_ok": g.windows_ok,
        "ljung_box_p": g.ljung.p_min_adjusted, "ljung_box_max_lag": g.ljung.max_lag, "max_abs_rho": g.max_abs_rho,
        "whiteness_ok": g.whiteness_ok, "consistent": g.consistent,
    })


def _tables(r: GyrolessResult) -> dict[str, dict[str, np.ndarray]]:
    f = r.filtered
    att = {
        "time_tai_ns": r.time_tai_ns,
        **{f"q{i}": r.q_OB[:, i] for i in range(4)},
        "roll_deg": r.roll_rad * DEG_PER_RAD, "pitch_deg": r.pitch_rad * DEG_PER_RAD,
        "yaw_deg": r.yaw_rad * DEG_PER_RAD,
        **{f"sigma_{a}_deg": r.attitude_sigma_rad[:, i] * DEG_PER_RAD for i, a in enumerate("xyz")},
        **{f"w_bi_{a}_rad_s": r.omega_BI_B[:, i] for i, a in enumerate("xyz")},
        **{f"w_bo_{a}_rad_s": r.omega_BO_B[:, i] for i, a in enumerate("xyz")},
        **{f"w_sigma_{a}_rad_s": r.rate_sigma_rad_s[:, i] for i, a in enumerate("xyz")},
        "tau_d_x_N_m": r.tau_d_O_N_m[:, 0], "tau_d_y_N_m": r.tau_d_O_N_m[:, 1],
        **{f"q_ib_{i}": r.q_IB[:, i] for i in range(4)},
        "sun_used": r.sun_used.astype(bool),
    }
    for name, (v, sig) in r.model_errors.items():
        base = {"magnetometer_bias_B_nT": "mag_bias", "field_error_O_nT": "field_error"}[name]
        for i, a in enumerate("xyz"):
            att[f"{base}_{a}_nT"] = v[:, i]
            att[f"{base}_{a}_sigma_nT"] = sig[:, i]
    if r.smoothed is not None:
        from processing.attitude.rigid_body import roll_pitch_yaw_004

        fr, fp, fy = roll_pitch_yaw_004(f.q_OB)
        att.update({"roll_filtered_deg": fr * DEG_PER_RAD, "pitch_filtered_deg": fp * DEG_PER_RAD,
                    "yaw_filtered_deg": fy * DEG_PER_RAD,
                    **{f"sigma_{a}_filtered_deg": f.attitude_sigma_rad[:, i] * DEG_PER_RAD
                       for i, a in enumerate("xyz")}})
    innov = {"time_tai_ns": r.time_tai_ns, "nis": r.nis, "nis_dof": r.nis_dof,
             "magnetometer_residual_deg": f.residual_rad[:, 0] * DEG_PER_RAD,
             "sun_residual_deg": f.residual_rad[:, 1] * DEG_PER_RAD}
    return {"attitude": att, "innovations": innov}


def _shade_outages(ax: Any, result: TaskResult, t0: int) -> None:
    for o in result.summary["sun_outages"]:
        ax.axvspan((o["start_tai_ns"] - t0) / NS_PER_S, (o["end_tai_ns"] - t0) / NS_PER_S, color="0.85", lw=0)


def _seconds(result: TaskResult) -> tuple[np.ndarray, int]:
    att = result.tables["attitude"]
    t0 = int(att["time_tai_ns"][0])
    return (np.asarray(att["time_tai_ns"], dtype=np.int64) - t0) / NS_PER_S, t0


def _fig_attitude(result: TaskResult, label: str) -> Figure:
    att = result.tables["attitude"]
    ts, t0 = _seconds(result)
    fig = Figure(figsize=(10, 7), layout="constrained", label="Attitude angles in the orbital frame (004 figs. 3-7)")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, name, sig in zip(axes, ("roll", "pitch", "yaw"), ("x", "y", "z"), strict=True):
        _shade_outages(ax, result, t0)
        y, s = np.asarray(att[f"{name}_deg"]), np.asarray(att[f"sigma_{sig}_deg"])
        if f"{name}_filtered_deg" in att:
            ax.plot(ts, att[f"{name}_filtered_deg"], color="tab:orange", lw=0.6, label="filtered")
        ax.plot(ts, y, color="tab:blue", lw=0.8, label=label)
        ax.fill_between(ts, y - s, y + s, color="tab:blue", alpha=0.25, lw=0, label="±1σ")
        ax.set_ylabel(f"{name} [deg]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since start [s] (grey: no sun sensor)")
    return fig


def _fig_sigma(result: TaskResult, label: str) -> Figure:
    att = result.tables["attitude"]
    ts, t0 = _seconds(result)
    conv = result.summary.get("time_to_converge_s")
    start = conv if conv is not None else 0.0
    m = ts >= start
    fig = Figure(figsize=(10, 7), layout="constrained", label="Attitude estimation 1-sigma bounds after convergence")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, sig in zip(axes, ("x", "y", "z"), strict=True):
        _shade_outages(ax, result, t0)
        ax.plot(ts[m], np.asarray(att[f"sigma_{sig}_deg"])[m], color="tab:blue", lw=0.8, label=label)
        if f"sigma_{sig}_filtered_deg" in att:
            ax.plot(ts[m], np.asarray(att[f"sigma_{sig}_filtered_deg"])[m], color="tab:orange", lw=0.8,
                    label="filtered")
        ax.set_ylabel(f"σ about {sig} [deg]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since start [s]")
    return fig


def _fig_rates(result: TaskResult) -> Figure:
    att = result.tables["attitude"]
    ts, t0 = _seconds(result)
    fig = Figure(figsize=(10, 7), layout="constrained", label="Body rate relative to the orbital frame with ±1σ")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, a in zip(axes, "xyz", strict=True):
        _shade_outages(ax, result, t0)
        w = np.asarray(att[f"w_bo_{a}_rad_s"]) * DEG_PER_RAD
        s = np.asarray(att[f"w_sigma_{a}_rad_s"]) * DEG_PER_RAD
        ax.plot(ts, w, lw=0.8)
        ax.fill_between(ts, w - s, w + s, alpha=0.25, lw=0)
        ax.set_ylabel(f"w_BO {a} [deg/s]")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time since start [s]")
    return fig


def _fig_consistency(result: TaskResult) -> Figure:
    inn = result.tables["innovations"]
    ts, _ = _seconds(result)
    fig = Figure(figsize=(10, 6), layout="constrained", label="Filter consistency: NIS and innovation whiteness")
    ax1, ax2 = fig.subplots(2, 1)
    nis, dof = np.asarray(inn["nis"], dtype=float), np.asarray(inn["nis_dof"], dtype=float)
    ok = np.isfinite(nis)
    ax1.plot(ts[ok], nis[ok], ".", ms=1.5, color="0.5", label="NIS")
    if np.any(ok):
        from processing.estimation.chi2 import chi2_ppf

        win = max(1, int(round(300 / max(result.summary.get("step_s") or 1.0, 1e-9))))
        kern = np.ones(win) / win
        ax1.plot(ts[ok], np.convolve(nis[ok], kern, mode="same"), color="tab:blue", label=f"mean over {win} steps")
        ax1.plot(ts[ok], chi2_ppf(0.975, dof[ok]), color="tab:red", lw=0.8, label="95 % per step")
        ax1.plot(ts[ok], dof[ok], color="k", lw=0.8, label="dof")
    ax1.set_ylabel("NIS")
    ax1.set_xlabel("time since start [s]")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.grid(alpha=0.3)
    w = result.summary["whiteness"]
    rho = np.array([[np.nan if v is None else v for v in row] for row in (w.get("rho") or [])], dtype=float)
    lags = np.arange(1, rho.shape[1] + 1) if rho.ndim == 2 else np.zeros(0)
    for c in range(rho.shape[0] if rho.ndim == 2 else 0):
        ax2.plot(lags + 0.1 * c, rho[c], "o", ms=3, label=f"component {c}")
    ax2.axhline(w["bound"] if w["bound"] is not None else 0, color="tab:red", lw=0.8)
    ax2.axhline(-(w["bound"] or 0), color="tab:red", lw=0.8)
    ax2.set_title(f"whitened innovations: {100 * (w['fraction_outside'] or 0):.1f} % of autocorrelations outside "
                  f"±{w['bound'] or 0:.3f} (lags 1-{w['max_lag']})", fontsize=9)
    ax2.set_xlabel("lag [steps]")
    ax2.set_ylabel("autocorrelation")
    ax2.grid(alpha=0.3)
    return fig


def _fig_disturbance(result: TaskResult) -> Figure:
    att = result.tables["attitude"]
    ts, _ = _seconds(result)
    fig = Figure(figsize=(10, 4), layout="constrained", label="Estimated disturbance torque (orbital x, y)")
    ax = fig.add_subplot()
    ax.plot(ts, att["tau_d_x_N_m"], label="τd x_O")
    ax.plot(ts, att["tau_d_y_N_m"], label="τd y_O")
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("N m")
    ax.legend()
    ax.grid(alpha=0.3)
    return fig


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    label = "smoothed" if params.smoother else "filtered"
    return {"attitude": _fig_attitude(result, label), "attitude_sigma": _fig_sigma(result, label),
            "rates": _fig_rates(result), "consistency": _fig_consistency(result),
            "disturbance": _fig_disturbance(result)}


JOB = JobType(
    name="gyroless_ekf", title="Gyroless attitude from magnetometer and sun sensor (EKF)", paper="004",
    params=Params, run=run, streams=("magnetometer", "sun_sensor", "gnss"), optional_streams=("magnetorquer",),
    figures=figures,
    figure_names=always("attitude", "attitude_sigma", "rates", "consistency", "disturbance"),
    applies_calibration="magnetometer",
    description="Attitude q_OB (orbital frame of 004), rates and in-plane disturbance torque from magnetometer, "
                "sun sensor and GNSS with the EKF of paper 004 or a multiplicative EKF, plus an RTS smoother; "
                "reference field IGRF-14, Sun from ERFA; consistency by NIS and innovation whiteness.",
    headline=(*(Answer(f"{a}_deg.mean", f"{a.capitalize()}, mean over the window", sigma=f"{a}_deg.std",
                       sigma_label="std", frame="body B in the orbital frame O (004)")
                for a in ("roll", "pitch", "yaw")),
              Answer("attitude_sigma_deg.median", "Attitude estimate 1σ (median)", frame="about the body axes (B)"),
              Answer("converged", "Filter converged")),
)
