"""Job ``magnetometer_calibration``: bias, scale factors, non-orthogonality (and magnetorquer coupling) of the
magnetometer from its own telemetry, attitude-independent, by |B| matching against IGRF-14 along the GNSS orbit
(processing.magnetometer.calibration: TWOSTEP of Alonso & Shuster 2002 with a bias-corrected Gauss-Newton).

Model (frame M, nT): B_meas = (I + D) B_true + b + C mu_B + n, D symmetric: ``scale_factors`` = 1 + D_ii,
``non_orthogonality_rad`` = (D_xy, D_xz, D_yz), ``coupling_nT_per_A_m2`` = C (rows magnetometer axes, columns
body dipole axes; the dipole of the latest magnetorquer sample at or before each magnetometer sample). A
rotation of the sensor is invisible to |B| (it stays in the configured q_BM). Values the arc does not determine
(sigma above the tolerance) are null with ``*_observable: false``; then ``calibration_complete`` is false and no
calibration version is stored. A complete result stores a version of kind ``magnetometer`` that gyroless_ekf and
vector_attitude apply (B_true_est = (I + D)^-1 (B_meas - b - C mu)) when given as their calibration.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType, always
from app.reports.headline import Answer
from app.reports.sections import ReportContext, ReportSection, ReportTable
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import NS_PER_S

TABLE_MAX_ROWS = 50_000
"""The residual table keeps every k-th sample so that it has at most this many rows."""


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    estimate_coupling: bool = Field(False, description="also estimate the magnetorquer coupling C (3x3, needs "
                                                       "magnetorquer telemetry with a varying dipole)")
    magnetometer_noise_nT: float | None = Field(None, gt=0, le=1e5, description="stated sensor noise, 1 sigma per "
                                                "axis: the residuals are tested against it (chi-square); None: "
                                                "the residual variance alone")
    field_model_error_nT: float = Field(0.0, ge=0, le=1e5, description="field-model error (crustal/external) "
                                        "added in quadrature to the expected residual variance")
    max_bias_sigma_nT: float = Field(50.0, gt=0, description="a bias component with a larger sigma is not "
                                     "observable")
    max_scale_sigma: float = Field(5e-3, gt=0, description="scale-factor and non-orthogonality tolerance")
    max_coupling_sigma_nT_per_A_m2: float = Field(10.0, gt=0)
    outlier_sigma: float | None = Field(6.0, gt=3, description="reject |residual| > this x the robust sigma; "
                                        "None: keep all")
    max_gnss_gap_s: float = Field(120.0, gt=0, le=3600)
    max_torquer_gap_s: float = Field(10.0, gt=0, le=3600, description="a magnetometer sample whose latest "
                                     "magnetorquer sample is older is not used (coupling only)")
    magnetometer_sensor: str | None = Field(None, description="sensor name; default the only one in the data")


def _floats(x: Any) -> list[Any]:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim > 1:
        return [_floats(row) for row in a]
    return [float(v) if np.isfinite(v) else None for v in a.reshape(-1)]


def _dipole_at(inputs: TaskInputs, t_mag: np.ndarray, max_gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Dipole (N, 3) of the latest magnetorquer sample at or before each magnetometer instant, and the mask of
    the instants that have one within max_gap_s."""
    if not inputs.sensors("magnetorquer"):
        raise TaskError("estimate_coupling needs magnetorquer samples in the job window")
    tq = inputs.magnetorquer()
    i = np.searchsorted(tq.time_tai_ns, t_mag, side="right") - 1
    ok = i >= 0
    ic = np.clip(i, 0, None)
    ok &= (t_mag - tq.time_tai_ns[ic]) <= max_gap_s * NS_PER_S
    return tq.m_B_A_m2[ic], ok


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    from processing.magnetometer.calibration import (
        CalibrationSettings,
        MagnetometerCalibrationError,
        calibrate_magnetometer,
    )
    from processing.magnetometer.reference import reference_field_norm_nT

    progress(0.05, "loading magnetometer and GNSS")
    mag = inputs.magnetometer(params.magnetometer_sensor)
    gnss = inputs.gnss()
    t = mag.time_tai_ns
    keep = np.concatenate([[True], np.diff(t) > 0]) & np.all(np.isfinite(mag.b_M_nT), axis=1)
    progress(0.15, "IGRF-14 along the GNSS orbit")
    ref, ok = reference_field_norm_nT(t, gnss.time_tai_ns, gnss.r_E_m, gnss.v_E_m_s,
                                      max_gnss_gap_s=params.max_gnss_gap_s)
    ok &= keep
    mu = None
    if params.estimate_coupling:
        mu_all, ok_mu = _dipole_at(inputs, t, params.max_torquer_gap_s)
        ok &= ok_mu
    notes = []
    if not np.all(ok):
        notes.append(f"{int(np.sum(~ok))} of {t.size} magnetometer samples not used (outside the GNSS span, in a "
                     "GNSS or magnetorquer gap, repeated time tags or not finite)")
    t, H, ref = t[ok], mag.b_M_nT[ok], ref[ok]
    if params.estimate_coupling:
        mu = mu_all[ok]
    if t.size < 50:
        raise TaskError(f"only {t.size} magnetometer samples with a reference field; at least 50 are needed")
    period = float(np.median(np.diff(t))) / NS_PER_S
    settings = CalibrationSettings(
        estimate_coupling=params.estimate_coupling, magnetometer_noise_nT=params.magnetometer_noise_nT,
        field_model_error_nT=params.field_model_error_nT, max_bias_sigma_nT=params.max_bias_sigma_nT,
        max_scale_sigma=params.max_scale_sigma, max_coupling_sigma_nT_per_A_m2=params.max_coupling_sigma_nT_per_A_m2,
        outlier_sigma=params.outlier_sigma)
    progress(0.3, "|B| matching (TWOSTEP + Gauss-Newton)")
    try:
        cal = calibrate_magnetometer(H, ref, sample_period_s=period, mu_B_A_m2=mu, settings=settings)
    except MagnetometerCalibrationError as exc:
        raise TaskError(str(exc)) from exc
    progress(0.85, "summary and tables")
    summary = _summary(cal, params, t, period, mag.sensor)
    step = max(1, -(-t.size // TABLE_MAX_ROWS))
    table = {"time_tai_ns": t[::step], "field_reference_nT": ref[::step],
             "residual_before_nT": cal.residual_before_nT[::step], "residual_after_nT": cal.residual_after_nT[::step],
             "used": cal.used[::step]}
    return TaskResult(summary=summary, tables={"field_residuals": table}, notes=notes + list(cal.notes),
                      warnings=_warnings(cal, params, period))


def _summary(cal: Any, params: Params, t: np.ndarray, period: float, sensor: str) -> dict[str, Any]:
    p, sig, obs = cal.estimate, cal.sigma, cal.observable
    val = np.where(obs, p, np.nan)
    used = cal.used

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x[used] ** 2)))

    out: dict[str, Any] = {
        "sensor": sensor,
        "n_samples": int(t.size),
        "n_used": int(np.sum(used)),
        "sample_period_s": period,
        "start_tai_ns": int(t[0]),
        "end_tai_ns": int(t[-1]),
        "model": "B_meas = (I + D) B_true + b + C mu_B + n (frame M, nT); D symmetric: scale factor 1 + D_ii, "
                 "non-orthogonality (D_xy, D_xz, D_yz) rad",
        "bias_nT": _floats(val[0:3]),
        "bias_sigma_nT": _floats(sig[0:3]),
        "bias_observable": [bool(v) for v in obs[0:3]],
        "scale_factors": _floats(1.0 + val[3:6]),
        "scale_factor_errors": _floats(val[3:6]),
        "scale_factor_sigma": _floats(sig[3:6]),
        "scale_factor_observable": [bool(v) for v in obs[3:6]],
        "non_orthogonality_rad": _floats(val[6:9]),
        "non_orthogonality_sigma_rad": _floats(sig[6:9]),
        "non_orthogonality_observable": [bool(v) for v in obs[6:9]],
        "non_orthogonality_axes": ["xy", "xz", "yz"],
    }
    if params.estimate_coupling:
        out.update({"coupling_nT_per_A_m2": _floats(val[9:18].reshape(3, 3)),
                    "coupling_sigma_nT_per_A_m2": _floats(sig[9:18].reshape(3, 3)),
                    "coupling_observable": obs[9:18].reshape(3, 3).tolist()})
    out.update({
        "residual_field_rms_before_nT": rms(cal.residual_before_nT),
        "residual_field_rms_after_nT": rms(cal.residual_after_nT),
        "residual_sigma_nT": cal.residual_sigma_nT,
        "iterations": cal.iterations,
        "converged": cal.converged,
        "information_singular_values_relative": _floats(cal.singular_values),
        "whiteness": {"ljung_box": cal.whiteness_statistic, "lags": cal.whiteness_dof, "p_value": cal.whiteness_p,
                      "rho_lag1": float(cal.rho[0]), "long_run_variance_factor": cal.long_run_factor,
                      "covariance_inflation": cal.inflation},
        "chi_square": (None if cal.chi2 is None else
                       {"statistic": cal.chi2[0], "dof": cal.chi2[1], "p_value": cal.chi2[2],
                        "ratio": cal.chi2[0] / cal.chi2[1]}),
        "parameter_names": list(cal.parameter_names),
        "correlation": _floats(cal.covariance / np.outer(sig, sig)),
        "calibration_complete": cal.complete,
        "calibration": _calibration(cal, sensor, t, params),
        "artifacts": {"field_residuals": "|B_meas| - |B_ref| before and |corrected| - |B_ref| after, per sample"},
    })
    return out


def _calibration(cal: Any, sensor: str, t: np.ndarray, params: Params) -> dict[str, Any]:
    e = cal.errors
    return {"kind": "magnetometer", "sensor": sensor, "valid_from_tai_ns": int(t[0]), "valid_to_tai_ns": int(t[-1]),
            "bias_nT": _floats(e.bias_nT), "D": _floats(e.D),
            "coupling_nT_per_A_m2": _floats(e.coupling_nT_per_A_m2) if params.estimate_coupling else None,
            "model": "B_true = (I + D)^-1 (B_meas - b - C mu_B)", "complete": cal.complete}


def _warnings(cal: Any, params: Params, period: float) -> list[ResultWarning]:
    out = []
    bad = [n for n, o in zip(cal.parameter_names, cal.observable, strict=True) if not o]
    if bad:
        arc_s = cal.residual_before_nT.size * period
        out.append(ResultWarning(
            "not_observable",
            f"the arc ({arc_s:.0f} s) does not determine {', '.join(bad)}: null, and no calibration version. "
            "|B| matching needs the field direction to turn through the magnetometer axes: at least one orbit, "
            "better a few (the field direction in a nadir-pointing frame stays near the orbit plane; attitude "
            "motion or a longer arc helps)" + ("; the coupling needs a dipole that varies on every axis"
                                               if params.estimate_coupling else ""),
            {"parameters": bad, "sigma": {n: float(s) for n, s, o in zip(cal.parameter_names, cal.sigma,
                                                                          cal.observable, strict=True) if not o},
             "tolerances": {"bias_nT": params.max_bias_sigma_nT, "scale": params.max_scale_sigma,
                            "coupling_nT_per_A_m2": params.max_coupling_sigma_nT_per_A_m2},
             "singular_values_relative": _floats(cal.singular_values)}))
    if cal.inflation > 1.0:
        out.append(ResultWarning(
            "correlated_residuals",
            f"the |B| residuals are not white (Ljung-Box p = {cal.whiteness_p:.2g}, lag-1 autocorrelation "
            f"{cal.rho[0]:.2f}; field-model error along the orbit?): the sigmas are inflated by "
            f"sqrt({cal.inflation:.2f})",
            {"ljung_box": cal.whiteness_statistic, "lags": cal.whiteness_dof, "p_value": cal.whiteness_p,
             "inflation": cal.inflation}))
    n_out = int(np.sum(~cal.used))
    if n_out:
        out.append(ResultWarning("outliers_removed", f"{n_out} samples with |residual| above {params.outlier_sigma} "
                                 "robust sigma were rejected before the fit",
                                 {"n_rejected": n_out, "threshold_sigma": params.outlier_sigma}))
    if cal.chi2 is not None and cal.chi2[2] < 1e-3:
        ratio = cal.chi2[0] / cal.chi2[1]
        out.append(ResultWarning(
            "implausible_input",
            f"the |B| residuals are {'larger' if ratio > 1 else 'smaller'} than the stated noise "
            f"({params.magnetometer_noise_nT} nT, field-model error {params.field_model_error_nT} nT): chi-square "
            f"per dof {ratio:.2f}; the sigmas use the residual variance",
            {"chi2": cal.chi2[0], "dof": cal.chi2[1], "p_value": cal.chi2[2]}))
    if not cal.converged and not bad:
        out.append(ResultWarning("not_observable", f"the fit did not converge in {cal.iterations} iterations "
                                 "(a weakly determined direction): no calibration version",
                                 {"iterations": cal.iterations}))
    return out


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    tab = result.tables["field_residuals"]
    t0 = int(tab["time_tai_ns"][0])
    ts = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    s = result.summary
    fig = Figure(figsize=(9, 5), layout="constrained", label="|B| residual against IGRF-14, before and after "
                                                             "the calibration")
    ax = fig.add_subplot()
    ax.plot(ts, tab["residual_before_nT"], lw=0.6, color="tab:red",
            label=f"before (rms {s['residual_field_rms_before_nT']:.0f} nT)")
    ax.plot(ts, tab["residual_after_nT"], lw=0.6, color="tab:blue",
            label=f"after (rms {s['residual_field_rms_after_nT']:.0f} nT)")
    ax.set_xlabel("time since the first sample [s]")
    ax.set_ylabel("|B_meas| - |B_IGRF| [nT]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return {"field_residuals": fig}


def report_sections(ctx: ReportContext) -> list[ReportSection]:
    s = ctx.summary
    rows: list[tuple[Any, ...]] = []
    for key, sig, obs, names, unit in (
            ("bias_nT", "bias_sigma_nT", "bias_observable", "xyz", "nT"),
            ("scale_factor_errors", "scale_factor_sigma", "scale_factor_observable", "xyz", "-"),
            ("non_orthogonality_rad", "non_orthogonality_sigma_rad", "non_orthogonality_observable",
             ("xy", "xz", "yz"), "rad")):
        for i, n in enumerate(names):
            rows.append((key, n, s[key][i], s[sig][i], unit, "yes" if s[obs][i] else "NO"))
    if "coupling_nT_per_A_m2" in s:
        for i in range(3):
            for j in range(3):
                rows.append(("coupling_nT_per_A_m2", f"{'xyz'[i]}<-mu_{'xyz'[j]}", s["coupling_nT_per_A_m2"][i][j],
                             s["coupling_sigma_nT_per_A_m2"][i][j], "nT/(A m²)",
                             "yes" if s["coupling_observable"][i][j] else "NO"))
    w = s["whiteness"]
    paras = (f"Attitude-independent |B| matching against IGRF-14 along the GNSS orbit (TWOSTEP, Alonso & Shuster "
             f"2002). Residual |B| rms {s['residual_field_rms_before_nT']:.1f} nT before, "
             f"{s['residual_field_rms_after_nT']:.1f} nT after; residual sigma {s['residual_sigma_nT']:.1f} nT. "
             f"Whiteness: Ljung-Box p = {w['p_value']:.3g} over {w['lags']} lags (covariance inflation "
             f"{w['covariance_inflation']:.2f}).",
             "A parameter is observable when its sigma is below its tolerance; otherwise it is null and no "
             "calibration version is stored. A rotation of the magnetometer cannot be seen in |B|; it stays in the "
             "configured mounting q_BM.")
    return [ReportSection(title="Magnetometer calibration: estimates and what the arc determines", paragraphs=paras,
                          tables=(ReportTable(columns=("quantity", "axis", "value", "1σ", "unit", "observable"),
                                              rows=rows),),
                          figure_names=("field_residuals",))]


JOB = JobType(
    name="magnetometer_calibration", title="Magnetometer calibration (|B| matching against IGRF-14)", paper="",
    params=Params, run=run, streams=("magnetometer", "gnss"), optional_streams=("magnetorquer",),
    figures=figures,
    figure_names=always("field_residuals"), report_sections=report_sections, produces_calibration="magnetometer",
    headline=(Answer("bias_nT", "Magnetometer bias b", sigma="bias_sigma_nT", frame="magnetometer (M)"),
              Answer("scale_factor_errors", "Scale-factor errors D_ii", sigma="scale_factor_sigma", unit="ppm",
                     scale=1e6, frame="magnetometer (M)"),
              Answer("non_orthogonality_rad", "Non-orthogonality (D_xy, D_xz, D_yz)",
                     sigma="non_orthogonality_sigma_rad", components=("xy", "xz", "yz"), frame="magnetometer (M)"),
              Answer("residual_field_rms_after_nT", "|B| residual rms after calibration", unit="nT")),
    description="Magnetometer bias, scale factors and non-orthogonality (and optionally the magnetorquer coupling) "
                "from the magnetometer's own telemetry, attitude-independent: |B| matching against IGRF-14 along "
                "the GNSS orbit (TWOSTEP, Alonso & Shuster 2002), covariance from the Jacobian scaled by the "
                "residual variance, whiteness and chi-square checks, observability from the information matrix; "
                "undetermined values are null. A complete result is a calibration version of kind magnetometer.",
)
