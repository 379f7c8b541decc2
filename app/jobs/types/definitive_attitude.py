"""Job ``definitive_attitude`` (beyond 003/000): the smoothed attitude of a whole arc from every star-tracker
head and the gyros, with its per-axis sigma, the bias history, the calibration with covariance and
observability, and the filter's consistency (NIS, innovation whiteness).

Thin layer over :func:`processing.definitive.estimate.estimate_definitive_attitude` (MEKF + RTS smoother with
augmented scale-factor, misalignment, head-mounting and time-offset states; see processing/definitive). It
picks the heads (every configured one with data; the first is the reference), the gyro stream, turns the
parameters into settings, and builds the summary (undetermined states null with ``*_observable: false``),
the tables (attitude with sigma, bias history, residuals), a CCSDS AEM of q_IB, warnings, figures and the
report sections, including the side-by-side comparison with gyro_bias_fit and alignment_calibration's
processing when ``compare_with`` asks for it.
"""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.plausibility import check_heads, midpoint_rates
from app.jobs.registry import JobType, always
from app.reports.headline import Answer
from app.reports.sections import ReportContext, ReportSection, ReportTable
from processing.definitive.comparison import compare_alignment, compare_gyro_bias_fit
from processing.definitive.estimate import DefinitiveResult, estimate_definitive_attitude
from processing.definitive.inputs import gyro_mounting, gyro_steps, star_tracker_heads
from processing.definitive.model import (
    K_ENTRIES,
    MISALIGNMENT_NAMES,
    DefinitiveError,
    DefinitiveSettings,
    misalignment_jacobian,
    misalignment_parts,
)
from processing.estimation.chi2 import chi2_ppf
from processing.formats.ccsds_adm import aem_segment, write_aem
from processing.star_tracker.multi_head import HeadSeries
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import ARCSEC_PER_RAD, NS_PER_S, RAD_PER_ARCSEC

AEM_FILE = "definitive_attitude.aem"
NIS_TOLERANCE = 0.1
"""filter_inconsistent when the mean NIS is outside its 95 % interval and off its dof by more than this
fraction (with tens of thousands of updates the interval alone is a few per mille wide: a slightly wrong noise
level would flag every arc), or when more than WHITENESS_MAX of the innovation autocorrelations exceed their
95 % bound (5 % expected)."""
WHITENESS_MAX = 0.10
TIME_OFFSET_MIN_S = 1e-3


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sensors: list[str] | None = Field(None, description="star-tracker heads, the first is the reference "
                                                        "(default: every configured head with data)")
    gyro_source: Literal["auto", "gyro", "gyro_increments"] = Field("auto", description="gyro stream (auto "
                                                                                      "prefers increments)")
    estimate_scale_factors: bool = Field(False, description="three gyro scale-factor errors")
    estimate_misalignment: bool = Field(False, description="the six misalignment/non-orthogonality terms "
                                                           "(Pittelkau)")
    estimate_head_mounting: bool = Field(False, description="mounting of each further head")
    estimate_time_offset: bool = Field(False, description="star-tracker time-tag offset against the gyro")
    gyro_arw_rad_sqrt_s: float | None = Field(None, gt=0, le=1e-2, description="angle random walk (default: "
                                                                               "from the gyro data)")
    bias_random_walk_rad_s_sqrt_s: float = Field(1e-9, ge=0, le=1e-4, description="bias (rate) random walk")
    star_tracker_sigma_arcsec: dict[str, tuple[float, float, float]] | None = Field(
        None, description="noise per head about x, y, z (default: from the residuals)")
    bias_sigma_rad_s: float = Field(1e-4, gt=0, le=1.0, description="prior sigma of the bias")
    scale_factor_sigma: float = Field(1e-2, gt=0, le=0.5)
    misalignment_sigma_arcsec: float = Field(200.0, gt=0, le=36_000)
    head_mounting_sigma_arcsec: float = Field(600.0, gt=0, le=36_000)
    time_offset_sigma_s: float = Field(0.1, gt=0, le=10)
    passes: int = Field(4, ge=1, le=8, description="most filter/smoother passes (noise re-estimation)")
    max_gyro_gap_s: float = Field(5.0, gt=0, le=600)
    gate_probability: float = Field(1e-6, ge=0, lt=0.5, description="outlier gate (0: none)")
    observability_threshold: float = Field(0.1, gt=0, lt=1)
    compare_with: list[Literal["gyro_bias_fit", "alignment_calibration"]] = Field(
        default_factory=list, description="also run these papers' estimators on the window, for the report")
    inertial_frame: str = Field("GCRF", max_length=40, pattern=r"^[A-Z0-9_]+$",
                                description="REF_FRAME_A of the AEM (the star trackers' frame)")
    aem_object_name: str = Field("UNKNOWN", max_length=100, pattern=r"^[^\n\r=]*$")
    aem_object_id: str = Field("UNKNOWN", max_length=100, pattern=r"^[^\n\r=]*$")

    def settings(self) -> DefinitiveSettings:
        return DefinitiveSettings(
            estimate_scale_factors=self.estimate_scale_factors, estimate_misalignment=self.estimate_misalignment,
            estimate_head_mounting=self.estimate_head_mounting, estimate_time_offset=self.estimate_time_offset,
            gyro_arw_rad_sqrt_s=None if self.gyro_arw_rad_sqrt_s is None else (self.gyro_arw_rad_sqrt_s,) * 3,
            bias_random_walk_rad_s_sqrt_s=self.bias_random_walk_rad_s_sqrt_s,
            star_tracker_sigma_rad={k: (v[0] * RAD_PER_ARCSEC, v[1] * RAD_PER_ARCSEC, v[2] * RAD_PER_ARCSEC)
                                    for k, v in (self.star_tracker_sigma_arcsec or {}).items()},
            bias_sigma_rad_s=self.bias_sigma_rad_s, scale_factor_sigma=self.scale_factor_sigma,
            misalignment_sigma_rad=self.misalignment_sigma_arcsec * RAD_PER_ARCSEC,
            head_mounting_sigma_rad=self.head_mounting_sigma_arcsec * RAD_PER_ARCSEC,
            time_offset_sigma_s=self.time_offset_sigma_s, passes=self.passes, max_gyro_gap_s=self.max_gyro_gap_s,
            gate_probability=self.gate_probability, observability_threshold=self.observability_threshold)


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


def _masked(values: Any, determined: Any) -> list[float | None]:
    return [float(v) if d and np.isfinite(v) else None for v, d in zip(np.ravel(values), np.ravel(determined),
                                                                         strict=True)]


def _calibration(r: DefinitiveResult) -> dict[str, Any]:
    lay, det = r.layout, dict(zip(r.state_names, r.observability.determined, strict=True))
    cov = r.parameter_covariance
    idx = {entry: j for j, entry in enumerate(lay.calibration)}
    out: dict[str, Any] = {"K": r.K, "parameter_names": r.state_names[6:], "covariance": cov}
    if all(i in idx for i in range(3)):
        names = [r.state_names[6 + idx[i]] for i in range(3)]
        ok = [bool(det[n]) for n in names]
        out.update(scale_factor=_masked([r.K[K_ENTRIES[i]] for i in range(3)], ok),
                   scale_factor_sigma=[float(np.sqrt(cov[idx[i], idx[i]])) for i in range(3)],
                   scale_factor_observable=ok)
    if all(i in idx for i in range(3, 9)):
        sel = [idx[i] for i in range(3, 9)]
        J = misalignment_jacobian()
        cd = J @ cov[np.ix_(sel, sel)] @ J.T
        delta, non_orth = misalignment_parts(r.K)
        ok6 = [bool(det[n]) for n in MISALIGNMENT_NAMES]
        rot_ok = [ok6[3] and ok6[5], ok6[1] and ok6[4], ok6[0] and ok6[2]]  # the pairs that make each component
        no_ok = [ok6[0] and ok6[2], ok6[1] and ok6[4], ok6[3] and ok6[5]]
        out.update(misalignment_rad=_masked(delta, rot_ok), misalignment_sigma_rad=np.sqrt(np.diag(cd)[:3]),
                   misalignment_observable=rot_ok, non_orthogonality_rad=_masked(non_orth, no_ok),
                   non_orthogonality_sigma_rad=np.sqrt(np.diag(cd)[3:]), non_orthogonality_observable=no_ok)
    mounts = {}
    for h, name in enumerate(lay.heads):
        q, rv, sig = r.head_mountings[name]
        sl = lay.mount(h)
        if sl is None:
            continue
        ok = [bool(det[f"mount_{name}_{a}"]) for a in "xyz"]
        mounts[name] = {"q_BS": q if all(ok) else None, "correction_rad": _masked(rv, ok), "sigma_rad": sig,
                        "observable": ok}
    if mounts:
        out["head_mountings"] = mounts
    if lay.time_offset:
        ok1 = bool(det["time_offset"])
        out.update(time_offset_s=r.time_offset_s if ok1 else None, time_offset_sigma_s=r.time_offset_sigma_s,
                   time_offset_observable=ok1)
    return out


def _summary(r: DefinitiveResult, params: Params) -> dict[str, Any]:
    det = dict(zip(r.state_names, r.observability.determined, strict=True))
    b_ok = [bool(det[f"bias_{a}"]) for a in "xyz"]
    bB = r.bias_B_rad_s
    sig = r.attitude_sigma_rad * ARCSEC_PER_RAD
    nis, wh = r.nis_stats, r.whiteness_stats
    per_head = {name: {"n_samples": int(np.count_nonzero(r.meas_head == h)),
                       "n_rejected": int(np.count_nonzero((r.meas_head == h) & ~r.used)),
                       "sigma_arcsec": r.star_tracker_sigma_rad[name] * ARCSEC_PER_RAD,
                       "sigma_source": r.star_tracker_sigma_source[name],
                       "residual_rms_arcsec": np.sqrt(np.mean(r.residual_rad[(r.meas_head == h) & r.used] ** 2,
                                                              axis=0)) * ARCSEC_PER_RAD}
                for h, name in enumerate(r.layout.heads)}
    return _clean({
        "reference_sensor": r.layout.heads[0], "sensors": per_head, "gyro_stream": r.gyro_kind,
        "n_epochs": int(r.time_tai_ns.size), "start_tai_ns": int(r.time_tai_ns[0]),
        "end_tai_ns": int(r.time_tai_ns[-1]), "passes": r.passes,
        "attitude_sigma_arcsec": {"median": np.median(sig, axis=0), "max": np.max(sig, axis=0),
                                  "median_filtered": np.median(r.attitude_sigma_filtered_rad, axis=0) * ARCSEC_PER_RAD,
                                  "axes": "body x, y, z"},
        "gyro_bias_rad_s": _masked(bB.mean(axis=0), b_ok),
        "gyro_bias_sigma_rad_s": np.sqrt(np.mean(r.bias_sigma_G_rad_s**2, axis=0)),
        "gyro_bias_observable": b_ok,
        "gyro_bias_frame": "body (w_meas = w + b); history in the gyro_bias table",
        "gyro_bias_change_rad_s": _masked(bB[-1] - bB[0], b_ok),
        "calibration": _calibration(r),
        "observability": {n: {"determined": bool(d), "data_sigma_ratio": float(x)} for n, d, x in
                          zip(r.state_names, r.observability.determined, r.observability.data_sigma_ratio,
                              strict=True)},
        "nis": {"mean": nis.mean, "dof": nis.mean_dof, "mean_bounds_95": list(nis.mean_bounds),
                "mean_in_bounds": nis.mean_in_bounds, "fraction_in_95": nis.fraction_in_95, "n": nis.n},
        "nees": {"value": None, "reason": "NEES needs the true attitude; the simulation tests measure it"},
        "whiteness": {"bound": wh.bound, "fraction_outside": wh.fraction_outside, "max_abs_rho": wh.max_abs_rho,
                      "rho": wh.rho},
        "gyro_arw_rad_sqrt_s": r.gyro_arw_rad_sqrt_s, "gyro_arw_source": r.gyro_arw_source,
        "bias_random_walk_rad_s_sqrt_s": r.bias_random_walk_rad_s_sqrt_s,
        "max_second_order_rad": r.max_second_order_rad,
        "artifacts": {"attitude": "q_IB with 1-sigma about the body axes (smoothed and filtered), body rate",
                      "gyro_bias": "bias history in the gyro and body frames with 1-sigma",
                      "residuals": "star-tracker innovations and smoothed residuals per head, NIS, used",
                      AEM_FILE: "CCSDS AEM 2.0 of q_IB"},
    })


def _warnings(r: DefinitiveResult) -> list[ResultWarning]:
    out = []
    undetermined = [n for n, d in zip(r.state_names, r.observability.determined, strict=True) if not d]
    if undetermined:
        out.append(ResultWarning("not_observable", f"the arc does not determine {', '.join(undetermined)}: reported "
                                 "as null (a wider motion, a longer arc or fewer estimated states would)",
                                 {"states": undetermined, "data_sigma_ratio": [
                                     float(x) for n, x in zip(r.state_names, r.observability.data_sigma_ratio,
                                                              strict=True) if n in undetermined]}))
    nis, wh = r.nis_stats, r.whiteness_stats
    off = abs(nis.mean / nis.mean_dof - 1.0) if nis.n else 0.0
    if (nis.n and not nis.mean_in_bounds and off > NIS_TOLERANCE) or (np.isfinite(wh.fraction_outside)
                                                                       and wh.fraction_outside > WHITENESS_MAX):
        out.append(ResultWarning("filter_inconsistent", "the star-tracker innovations disagree with the filter's "
                                 "covariance: check the noise settings and the estimated states",
                                 {"nis_mean": nis.mean, "nis_dof": nis.mean_dof, "nis_bounds": list(nis.mean_bounds),
                                  "whiteness_fraction_outside": wh.fraction_outside,
                                  "whiteness_max": WHITENESS_MAX}))
    n_rej = int(np.count_nonzero(~r.used))
    if n_rej:
        out.append(ResultWarning("outliers_removed", f"{n_rej} star-tracker samples rejected by the innovation "
                                 "gate", {"n_rejected": n_rej, "n_samples": int(r.used.size)}))
    if r.time_offset_s is not None and r.time_offset_sigma_s is not None:
        if abs(r.time_offset_s) > max(3 * r.time_offset_sigma_s, TIME_OFFSET_MIN_S):
            out.append(ResultWarning("time_offset", f"the star-tracker time tags are {1e3 * r.time_offset_s:.2f} ms "
                                     "off the gyro's (estimated and corrected)",
                                     {"time_offset_s": r.time_offset_s, "sigma_s": r.time_offset_sigma_s}))
    return out


def _tables(r: DefinitiveResult) -> dict[str, dict[str, np.ndarray]]:
    a = ARCSEC_PER_RAD
    att: dict[str, np.ndarray] = {"time_tai_ns": r.time_tai_ns, **{f"q{i}": r.q_IB[:, i] for i in range(4)},
                                  **{f"sigma_{x}_arcsec": r.attitude_sigma_rad[:, i] * a for i, x in enumerate("xyz")},
                                  **{f"sigma_{x}_filtered_arcsec": r.attitude_sigma_filtered_rad[:, i] * a
                                     for i, x in enumerate("xyz")},
                                  **{f"w_{x}_rad_s": r.rate_B_rad_s[:, i] for i, x in enumerate("xyz")},
                                  "measured": r.measured}
    bB = r.bias_B_rad_s
    bias = {"time_tai_ns": r.time_tai_ns, **{f"bias_{x}_G_rad_s": r.bias_G_rad_s[:, i] for i, x in enumerate("xyz")},
            **{f"sigma_{x}_G_rad_s": r.bias_sigma_G_rad_s[:, i] for i, x in enumerate("xyz")},
            **{f"bias_{x}_B_rad_s": bB[:, i] for i, x in enumerate("xyz")}}
    names = np.array(r.layout.heads, dtype=object)[r.meas_head]
    res = {"time_tai_ns": r.meas_time_tai_ns, "sensor": names,
           **{f"innovation_{x}_arcsec": r.innovation_rad[:, i] * a for i, x in enumerate("xyz")},
           **{f"residual_{x}_arcsec": r.residual_rad[:, i] * a for i, x in enumerate("xyz")},
           "nis": r.nis, "used": r.used}
    return {"attitude": att, "gyro_bias": bias, "residuals": res}


def _aem(r: DefinitiveResult, params: Params) -> bytes:
    comments = ("Definitive attitude q_IB smoothed by the definitive_attitude job (MEKF + RTS smoother) from star "
                f"trackers {', '.join(r.layout.heads)} and the gyros.",
                f"1-sigma per body axis: median {np.round(np.median(r.attitude_sigma_rad, 0) * ARCSEC_PER_RAD, 3)} "
                "arcsec (full series in the attitude table).")
    seg = aem_segment(r.time_tai_ns, r.q_IB / np.linalg.norm(r.q_IB, axis=1, keepdims=True),
                      object_name=params.aem_object_name, object_id=params.aem_object_id,
                      ref_frame_a=params.inertial_frame, ref_frame_b="SC_BODY_1", time_system="UTC",
                      comments=comments)
    return write_aem([seg], originator="ATTITUDE-SERVICE", creation_date=dt.datetime.now(dt.UTC)).encode()


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    progress(0.02, "loading star trackers and gyro")
    heads = star_tracker_heads(inputs, params.sensors)
    steps = gyro_steps(inputs, params.gyro_source, params.max_gyro_gap_s)
    q_BG = gyro_mounting(inputs)
    try:
        r = estimate_definitive_attitude(steps, heads, q_BG, params.settings(),
                                         progress=lambda f, s: progress(0.05 + 0.75 * f, s))
    except DefinitiveError as exc:
        raise TaskError(str(exc)) from exc
    summary = _summary(r, params)
    notes = list(r.notes)
    t_mid, w_mid = midpoint_rates(steps.t_ns, steps.da_G)
    summary["plausibility"], plausible = check_heads(
        [HeadSeries(h.name, h.time_tai_ns, h.q_IS, h.q_BS) for h in heads], t_mid, w_mid, q_BG, notes)
    comparison: dict[str, Any] = {}
    for name in params.compare_with:
        progress(0.85, f"comparison with {name}")
        try:
            fn = compare_gyro_bias_fit if name == "gyro_bias_fit" else compare_alignment
            out = fn(r, steps, heads, q_BG)
        except ValueError as exc:
            out = {"available": False, "reason": f"{type(exc).__name__}: {exc}"}
        comparison[name] = _clean({k: v for k, v in out.items() if k not in ("q_IB_gyro_bias_fit", "time_tai_ns")})
    if comparison:
        summary["comparison"] = comparison
    progress(0.95, "tables and AEM")
    # with the time offset estimated as a state, the filter's own warning says it
    plausible = [w for w in plausible if not (w.code == "time_offset" and r.time_offset_s is not None)]
    return TaskResult(summary=summary, tables=_tables(r), notes=notes,
                      files={AEM_FILE: (_aem(r, params), "text/plain")}, warnings=plausible + _warnings(r))


# ---------------------------------------------------------------------------------------------------
# Figures and report sections.


def _seconds(t: Any) -> np.ndarray:
    t = np.asarray(t, dtype=np.int64)
    return (t - t[0]).astype(np.float64) / NS_PER_S


def _fig_sigma(result: TaskResult) -> Figure:
    att = result.tables["attitude"]
    t = _seconds(att["time_tai_ns"])
    fig = Figure(figsize=(10, 6), layout="constrained", label="Attitude 1-sigma per body axis: smoothed and filtered")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, a in zip(axes, "xyz", strict=True):
        ax.semilogy(t, att[f"sigma_{a}_filtered_arcsec"], color="tab:orange", lw=0.6, label="filtered")
        ax.semilogy(t, att[f"sigma_{a}_arcsec"], color="tab:blue", lw=0.9, label="smoothed")
        ax.set_ylabel(f"σ {a} [arcsec]")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since the first epoch [s]")
    return fig


def _fig_bias(result: TaskResult) -> Figure:
    b = result.tables["gyro_bias"]
    t = _seconds(b["time_tai_ns"])
    fig = Figure(figsize=(10, 6), layout="constrained", label="Gyro bias history (gyro axes) with ±3σ")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, a in zip(axes, "xyz", strict=True):
        v = np.asarray(b[f"bias_{a}_G_rad_s"]) * ARCSEC_PER_RAD
        s = np.asarray(b[f"sigma_{a}_G_rad_s"]) * ARCSEC_PER_RAD
        ax.fill_between(t, v - 3 * s, v + 3 * s, color="tab:blue", alpha=0.2, lw=0)
        ax.plot(t, v, color="tab:blue", lw=0.9)
        ax.set_ylabel(f"b {a} [arcsec/s]")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time since the first epoch [s]")
    return fig


def _fig_residuals(result: TaskResult) -> Figure:
    res = result.tables["residuals"]
    t = _seconds(res["time_tai_ns"])
    sensors = np.asarray(res["sensor"]).astype(str)
    used = np.asarray(res["used"], dtype=bool)
    fig = Figure(figsize=(10, 7), layout="constrained", label="Smoothed star-tracker residuals per sensor axis "
                                                             "(003 figs. 13b-c style)")
    axes = fig.subplots(3, 1, sharex=True)
    for name in sorted(set(sensors.tolist())):
        m = (sensors == name) & used
        for i, (ax, a) in enumerate(zip(axes, "xyz", strict=True)):
            ax.plot(t[m], np.asarray(res[f"residual_{a}_arcsec"])[m], ".", ms=1.5, label=name if i == 0 else None)
    for ax, a in zip(axes, "xyz", strict=True):
        ax.set_ylabel(f"sensor {a} [arcsec]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, markerscale=5)
    axes[-1].set_xlabel("time since the first sample [s]")
    return fig


def _fig_consistency(result: TaskResult) -> Figure:
    res = result.tables["residuals"]
    nis = np.asarray(res["nis"], dtype=float)
    t = _seconds(res["time_tai_ns"])
    fig = Figure(figsize=(10, 6), layout="constrained", label="Filter consistency: NIS per head and innovation "
                                                             "whiteness")
    ax1, ax2 = fig.subplots(2, 1)
    ok = np.isfinite(nis)
    ax1.semilogy(t[ok], nis[ok], ".", ms=1.2, color="0.5", label="NIS per head measurement")

    ax1.axhline(chi2_ppf(0.975, 3), color="tab:red", lw=0.8, label="95 % (3 dof)")
    ax1.axhline(3.0, color="k", lw=0.8, label="dof")
    ax1.set_xlabel("time since the first sample [s]")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.grid(alpha=0.3)
    w = result.summary["whiteness"]
    rho = np.array([[np.nan if v is None else v for v in row] for row in (w.get("rho") or [])], dtype=float)
    if rho.ndim == 2 and rho.size:
        lags = np.arange(1, rho.shape[1] + 1)
        for c in range(rho.shape[0]):
            ax2.plot(lags + 0.05 * c, rho[c], "o", ms=3)
        bound = w["bound"] or 0.0
        ax2.axhline(bound, color="tab:red", lw=0.8)
        ax2.axhline(-bound, color="tab:red", lw=0.8)
    ax2.set_xlabel("lag [updates]")
    ax2.set_ylabel("autocorrelation of whitened innovations")
    ax2.grid(alpha=0.3)
    return fig


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    return {"attitude_sigma": _fig_sigma(result), "gyro_bias": _fig_bias(result),
            "residuals": _fig_residuals(result), "consistency": _fig_consistency(result)}


def _fmt(v: Any, scale: float = 1.0) -> Any:
    return None if v is None else float(v) * scale


def report_sections(ctx: ReportContext) -> list[ReportSection]:
    s = ctx.summary
    sections = []
    obs = s.get("observability") or {}
    rows = [(name, "yes" if o["determined"] else "NO", o["data_sigma_ratio"]) for name, o in obs.items()]
    sections.append(ReportSection(
        title="States and what the arc determines",
        paragraphs=("Each state's sigma from the data alone (every other state unknown) over its prior sigma; a "
                    "state is determined below the observability threshold, otherwise it is reported as null "
                    "(DESIGN.md, honesty contract).",),
        tables=(ReportTable(columns=("state", "determined", "data sigma / prior sigma"), rows=rows),),
        figure_names=("attitude_sigma", "gyro_bias"),
    ))
    cmp = s.get("comparison") or {}
    for name, c in cmp.items():
        if not c.get("available", False):
            sections.append(ReportSection(title=f"Comparison with {name}", paragraphs=(c.get("reason", ""),)))
            continue
        table_rows = [(x["quantity"], x["axis"], x["unit"], x["ours"], x["ours_sigma"], x["theirs"], x["theirs_sigma"],
                       x["difference_over_combined_sigma"]) for x in c["rows"]]
        paras = [f"The definitive attitude's values beside {name}'s, computed on the same window; the last column is "
                 "the difference over the combined sigma (|z| < 3: agreement)."]
        if "attitude_rms_difference_rad" in c:
            d = np.asarray(c["attitude_rms_difference_rad"], dtype=float) * ARCSEC_PER_RAD
            paras.append(f"Attitude difference smoothed - {name} at the star-tracker samples, rms per body axis: "
                         f"{', '.join(f'{v:.2f}' for v in d)} arcsec.")
        sections.append(ReportSection(
            title=f"Side by side with {name}", paragraphs=tuple(paras),
            tables=(ReportTable(columns=("quantity", "axis", "unit", "definitive", "σ", name, "σ", "z"),
                                rows=table_rows),)))
    return sections


JOB = JobType(
    name="definitive_attitude", title="Definitive attitude over a whole arc (MEKF + RTS smoother)", paper="",
    params=Params, run=run, streams=("star_tracker",), optional_streams=("gyro", "gyro_increments"),
    figures=figures,
    figure_names=always("attitude_sigma", "gyro_bias", "residuals", "consistency"), report_sections=report_sections,
    headline=(Answer("attitude_sigma_arcsec.median", "Smoothed attitude 1σ, median over the arc", unit="arcsec",
                     frame="body (B), about its axes"),
              Answer("gyro_bias_rad_s", "Gyro bias b, arc mean (w_meas = w + b)", sigma="gyro_bias_sigma_rad_s",
                     frame="body (B)"),
              Answer("gyro_bias_change_rad_s", "Gyro bias change over the arc", frame="body (B)"),
              Answer("nis.mean", "Star-tracker NIS, mean (expected: its dof)", unit="")),
    description="Smoothed attitude q_IB with per-axis 1-sigma from every star-tracker head and the gyros (rates or "
                "increments): a multiplicative EKF and Rauch-Tung-Striebel smoother with the gyro bias as a random "
                "walk and optional scale factors, misalignment/non-orthogonality (Pittelkau), further heads' "
                "mountings and the time-tag offset; undetermined states are null; NIS and innovation whiteness; "
                "CCSDS AEM; optional side-by-side comparison with gyro_bias_fit and alignment_calibration.",
)
