"""Job ``gyro_noise``: overlapping Allan deviation of the gyros with angle random walk, bias instability and
rate random walk (IEEE Std 952 terms) and their 95 % confidence intervals (processing.signal.allan, on
allantools).

Two sources:

- ``rates`` (a quiet arc): the gyro rates as measured (increments divided by their interval). The motion
  of the spacecraft is part of the signal, so the arc must be quiet (inertial or a constant rate: a
  constant offset does not change the Allan deviation);
- ``residual``: the gyros against the star trackers after the definitive attitude
  (processing.definitive): the gyro increments, corrected by the smoothed calibration (K and the window's
  mean bias), are integrated from the smoothed attitude of the first epoch and compared with the reference
  head's measurements (mounting estimated when asked); the difference angle in the gyro axes is phase data
  whose Allan deviation shows the star-tracker noise as white angle noise (the Q term, tau^-1) and the gyro
  terms where they rise above it. Any motion is removed, at the price of that white-angle floor.

Undetermined terms (their interval reaches zero) are null with ``*_observable: false`` and their upper bound.
These values can be given to definitive_attitude (gyro_arw_rad_sqrt_s, bias_random_walk_rad_s_sqrt_s).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType, always
from app.reports.headline import Answer
from processing.attitude import rotations
from processing.definitive.estimate import estimate_definitive_attitude
from processing.definitive.gyro import refine
from processing.definitive.inputs import gyro_mounting, gyro_steps, star_tracker_heads
from processing.definitive.model import DefinitiveError, DefinitiveSettings
from processing.definitive.propagation import body_increments, node_attitudes
from processing.signal.allan import TERMS, AllanError, allan_deviation, fit_noise
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import DEG_PER_RAD, NS_PER_S, S_PER_HOUR

UNITS = {"angle_white_noise": ("rad", 1.0), "angle_random_walk": ("rad_sqrt_s", 1.0),
         "bias_instability": ("rad_s", 1.0), "rate_random_walk": ("rad_s_sqrt_s", 1.0)}
EDGE = {"angle_random_walk": ("deg_sqrt_h", DEG_PER_RAD * np.sqrt(S_PER_HOUR)),
        "bias_instability": ("deg_h", DEG_PER_RAD * S_PER_HOUR)}


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    source: Literal["rates", "residual"] = Field("rates", description="rates: a quiet arc's gyro data; residual: "
                                                                      "gyro against star tracker after the "
                                                                      "definitive attitude")
    gyro_source: Literal["auto", "gyro", "gyro_increments"] = Field("auto")
    sensors: list[str] | None = Field(None, description="residual: star-tracker heads (the first is compared)")
    estimate_scale_factors: bool = Field(False, description="residual: calibrate the scale factors first")
    estimate_misalignment: bool = Field(False, description="residual: calibrate the misalignment first")
    max_gyro_gap_s: float = Field(5.0, gt=0, le=600)


def _rates(inputs: TaskInputs, params: Params) -> tuple[np.ndarray, float, str, dict[str, Any]]:
    steps = gyro_steps(inputs, params.gyro_source, params.max_gyro_gap_s)
    dt = np.diff(steps.sample_t_ns).astype(np.float64) / NS_PER_S
    period = float(np.median(dt))
    if np.any(np.abs(dt - period) > 0.01 * period):
        raise TaskError("the gyro samples are not evenly spaced (gaps or jitter above 1 %); choose a window without "
                        "gaps for the Allan deviation")
    return steps.rate_samples_G, 1.0 / period, "rates", {"n_samples": steps.n_samples, "period_s": period}


def _residual_angles(inputs: TaskInputs, params: Params,
                     progress: Progress) -> tuple[np.ndarray, float, str, dict[str, Any]]:
    heads = star_tracker_heads(inputs, params.sensors)
    steps = gyro_steps(inputs, params.gyro_source, params.max_gyro_gap_s)
    q_BG = gyro_mounting(inputs)
    settings = DefinitiveSettings(estimate_scale_factors=params.estimate_scale_factors,
                                  estimate_misalignment=params.estimate_misalignment,
                                  estimate_head_mounting=len(heads) > 1)
    try:
        r = estimate_definitive_attitude(steps, heads, q_BG, settings,
                                         progress=lambda f, s: progress(0.05 + 0.6 * f, s))
    except DefinitiveError as exc:
        raise TaskError(str(exc)) from exc
    head = heads[0]
    t = head.time_tai_ns[(head.time_tai_ns >= r.time_tai_ns[0]) & (head.time_tai_ns <= r.time_tai_ns[-1])]
    period = float(np.median(np.diff(t))) / NS_PER_S
    k = np.round((t - t[0]).astype(np.float64) / NS_PER_S / period).astype(np.int64)
    if np.any(np.abs((t - t[0]) / NS_PER_S - k * period) > 0.01 * period):
        raise TaskError(f"star tracker {head.name} is not sampled on a regular grid; the residual mode needs one")
    rs = refine(steps, t)
    R_BG = rotations.quat_to_dcm(q_BG)
    M = np.asarray(np.linalg.inv(np.eye(3) + r.K), dtype=np.float64)
    F = node_attitudes(body_increments(rs, R_BG, M, r.bias_G_rad_s.mean(axis=0)))
    q0 = r.q_IB[np.searchsorted(r.time_tai_ns, t[0])]
    q_gyro = rotations.quat_multiply(q0, rotations.quat_multiply(rotations.quat_conjugate(F[rs.epoch_node[0]]),
                                                                 F[rs.epoch_node]))
    q_meas = rotations.quat_multiply(head.q_IS[np.isin(head.time_tai_ns, t)],
                                     rotations.quat_conjugate(r.head_mountings[head.name][0]))
    phi_B = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(q_gyro), q_meas))
    phi = np.full((int(k[-1]) + 1, 3), np.nan)
    phi[k] = phi_B @ R_BG  # gyro axes
    info = {"n_samples": int(t.size), "period_s": period, "reference_sensor": head.name,
            "definitive_passes": r.passes, "missing_samples": int(phi.shape[0] - t.size)}
    return phi, 1.0 / period, "angles", info


def _term_summary(fit: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in TERMS:
        t = fit.terms[name]
        unit, _ = UNITS[name]
        out[f"{name}_{unit}"] = [float(v) if d else None for v, d in zip(t.value, t.determined, strict=True)]
        out[f"{name}_ci95_{unit}"] = [[float(lo), float(hi)] for lo, hi in zip(t.lo, t.hi, strict=True)]
        out[f"{name}_observable"] = [bool(d) for d in t.determined]
        if name in EDGE:
            e_unit, scale = EDGE[name]
            out[f"{name}_{e_unit}"] = [float(v) * scale if d else None for v, d in zip(t.value, t.determined,
                                                                                       strict=True)]
    return out


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    progress(0.02, "loading the gyro")
    if params.source == "rates":
        data, rate, kind, info = _rates(inputs, params)
    else:
        data, rate, kind, info = _residual_angles(inputs, params, progress)
    progress(0.7, "Allan deviation (allantools)")
    try:
        fit, ad = fit_noise(allan_deviation(data, rate, kind))
    except AllanError as exc:
        raise TaskError(f"Allan deviation: {exc}") from exc
    terms = _term_summary(fit)
    undetermined = [f"{name} {'xyz'[i]}" for name in TERMS if name != "angle_white_noise"
                    for i, d in enumerate(fit.terms[name].determined) if not d]
    warnings = []
    if undetermined:
        warnings.append(ResultWarning("not_observable", f"the data do not determine {', '.join(undetermined)}: null, "
                                      "with the upper bound of the 95 % interval (a longer arc would)",
                                      {"terms": undetermined}))
    if np.any(fit.chi2_per_dof > 4.0):
        warnings.append(ResultWarning("implausible_input", "the Allan deviation does not follow the four-term noise "
                                      "model (motion in the data? choose a quiet arc or source=residual)",
                                      {"chi2_per_dof": fit.chi2_per_dof.tolist()}))
    summary = {"source": params.source, "data": kind, "rate_hz": rate, **info, **terms,
               "fit_chi2_per_dof": fit.chi2_per_dof.tolist(), "axes": "gyro x, y, z",
               "model": "sigma^2(tau) = 3 Q^2/tau^2 + N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 (IEEE Std 952)",
               "artifacts": {"allan_deviation": "tau, deviation per axis with 95 % bounds and the fitted model"}}
    table = {"tau_s": ad.tau_s, **{f"adev_{a}": ad.adev[:, i] for i, a in enumerate("xyz")},
             **{f"lo_{a}": ad.lo[:, i] for i, a in enumerate("xyz")},
             **{f"hi_{a}": ad.hi[:, i] for i, a in enumerate("xyz")},
             **{f"model_{a}": fit.model_adev[:, i] for i, a in enumerate("xyz")},
             "unit": np.full(ad.tau_s.size, "rad/s" if kind == "rates" else "rad/s (angle/tau)", dtype=object)}
    return TaskResult(summary=summary, tables={"allan_deviation": table}, warnings=warnings)


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    tab = result.tables["allan_deviation"]
    fig = Figure(figsize=(9, 6), layout="constrained", label="Overlapping Allan deviation with 95 % bounds and the "
                                                            "IEEE 952 model")
    ax = fig.add_subplot()
    tau = np.asarray(tab["tau_s"], dtype=float)
    for i, a in enumerate("xyz"):
        c = f"C{i}"
        y = np.asarray(tab[f"adev_{a}"], dtype=float)
        lo, hi = np.asarray(tab[f"lo_{a}"], dtype=float), np.asarray(tab[f"hi_{a}"], dtype=float)
        ax.errorbar(tau, y, yerr=[y - lo, hi - y], fmt="o", ms=3, color=c, label=f"axis {a}")
        ax.plot(tau, tab[f"model_{a}"], "-", color=c, lw=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("tau [s]")
    ax.set_ylabel("Allan deviation [rad/s]")
    s = result.summary
    arw = s.get("angle_random_walk_rad_sqrt_s") or []
    bi = s.get("bias_instability_rad_s") or []
    ax.set_title(f"ARW {arw} rad/sqrt(s); BI {bi} rad/s", fontsize=8)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return {"allan_deviation": fig}


JOB = JobType(
    name="gyro_noise", title="Gyro noise: Allan deviation, ARW, bias instability, RRW", paper="",
    params=Params, run=run, streams=(), optional_streams=("gyro", "gyro_increments", "star_tracker"),
    figures=figures, figure_names=always("allan_deviation"),
    headline=(Answer("angle_random_walk_deg_sqrt_h", "Angle random walk N", unit="deg/√h", frame="gyro (G)"),
              Answer("bias_instability_deg_h", "Bias instability B", unit="deg/h", frame="gyro (G)"),
              Answer("rate_random_walk_rad_s_sqrt_s", "Rate random walk K", unit="rad/s/√s", frame="gyro (G)"),
              Answer("angle_white_noise_rad", "Angle white noise Q", unit="rad", frame="gyro (G)")),
    description="Overlapping Allan deviation (allantools) of the gyro rates of a quiet arc, or of the gyro against "
                "the star tracker after the definitive attitude, with angle random walk, bias instability and rate "
                "random walk (IEEE Std 952) and their 95 % confidence intervals.",
)
