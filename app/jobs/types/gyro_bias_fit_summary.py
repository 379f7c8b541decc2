"""Job ``gyro_bias_fit``: what a fit becomes in the report - the window and outcome it describes, the warnings,
the summary, the tables, and the combination of the per-segment fits of an arc split at its gyro gaps.

The fit itself (window, plausibility, smoothing, Gauss-Newton, sub-intervals) is in
:mod:`app.jobs.types.gyro_bias_fit`, the figures in :mod:`app.jobs.types.gyro_bias_fit_figures`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from app.services.times import iso
from processing.attitude import rotations
from processing.gyro_calibration.bias_fit import RESIDUAL_CONSISTENCY_MAX, GyroBiasFit
from processing.gyro_calibration.subintervals import ConstancyTest
from processing.star_tracker.plausibility import PlausibilityResult
from processing.tasks import ResultWarning, TaskResult
from processing.units import ARCSEC_PER_RAD, NS_PER_S, RAD_PER_DEG

if TYPE_CHECKING:
    from app.jobs.types.gyro_bias_fit import Params

RATES_TABLE_MAX_ROWS = 20_000
"""The "rates" table (figure 13a) keeps every k-th gyro sample so that it has at most this many rows."""


def as_floats(x: Any) -> list[float]:
    return [float(v) for v in np.asarray(x, dtype=np.float64).reshape(-1)]


def bias_body(fit: GyroBiasFit, q_BG: NDArray[np.float64], cov: NDArray[np.float64]) -> tuple[Any, Any]:
    """Body-frame bias b_B = -R(q_BR) Delta (w_meas = w_true + b) and its sigma from cov (3x3 of Delta)."""
    r_br = rotations.quat_to_dcm(rotations.quat_multiply(q_BG, rotations.quat_conjugate(fit.q_RG)))
    b = -r_br @ fit.delta_R_rad_s
    return b, np.sqrt(np.diag(r_br @ cov @ r_br.T))


@dataclass(frozen=True)
class Window:
    """The window as the fit sees it: gyro rates on their grid and the star-tracker samples within
    the gyro span, times in s from ``epoch`` (the first gyro time), mountings relative to the
    reference tracker R (003 §2.4)."""

    names: list[str]
    q_BG: NDArray[np.float64]
    epoch: int
    t_g_ns: NDArray[np.int64]
    w_G: NDArray[np.float64]
    t_st_ns: NDArray[np.int64]
    q_IS: NDArray[np.float64]
    sensor_of: NDArray[Any]
    sensor_index: NDArray[np.int64]
    q_RS: NDArray[np.float64]
    q_RG: NDArray[np.float64]
    q_BS: dict[str, NDArray[np.float64]]

    @property
    def t_g(self) -> NDArray[np.float64]:
        return (self.t_g_ns - self.epoch).astype(np.float64) / NS_PER_S

    @property
    def t_st(self) -> NDArray[np.float64]:
        return (self.t_st_ns - self.epoch).astype(np.float64) / NS_PER_S


@dataclass(frozen=True)
class Outcome:
    """Everything the report needs: the window, the fits (whole segment and sub-intervals with their
    edges, s from the epoch, and kinds), the gyro noise used and the rates fitted."""

    window: Window
    params: Params
    fit: GyroBiasFit
    subs: list[GyroBiasFit | None]
    edges: NDArray[np.float64]
    kinds: list[tuple[str, int, int]]
    arw: NDArray[np.float64]
    arw_source: str
    w_ap: NDArray[np.float64] | None
    harmonics: int | None
    plausibility: dict[str, PlausibilityResult | str]
    time_offset_applied_s: float | None
    constancy: ConstancyTest | None

    @property
    def delta_covariance(self) -> NDArray[np.float64]:
        """Covariance of Delta to report (R axes): the fit's, plus the offsets' variation when they drift."""
        c = self.constancy
        return self.fit.covariance[3:6, 3:6] if c is None or c.constant else c.covariance


CAUSES = ("quaternion_convention", "implausible_input", "time_offset", "bias_not_constant")
"""Warnings that explain residuals beyond the noise."""


def _causes(warnings: list[ResultWarning]) -> list[str]:
    return sorted({w.code for w in warnings if w.code in CAUSES})


def fit_warnings(r: Outcome) -> list[ResultWarning]:
    """The plausibility findings of every tracker, the undetermined time offset, drifting offsets, and a fit
    whose residuals the noise does not explain (named after its likely cause when another warning has none)."""
    out: list[ResultWarning] = []
    ref = r.plausibility.get(r.window.names[0])
    for name, res in r.plausibility.items():
        if not isinstance(res, PlausibilityResult):
            continue
        for w in res.warnings:
            if w.code == "time_offset" and name == r.window.names[0] and r.time_offset_applied_s is not None:
                tau = r.time_offset_applied_s
                w = ResultWarning(w.code, f"{name}: the star-tracker samples were taken {1e3 * abs(tau):.1f} ± "
                                  f"{1e3 * (res.time_offset_sigma_s or 0.0):.1f} ms {'after' if tau > 0 else 'before'} "
                                  "their time tags, on the gyro's clock; the gyro times were corrected by it before "
                                  "the fit (fit_time_offset): correct the time tags at the source",
                                  {**w.evidence, "corrected": True})
            out.append(w)
    if isinstance(ref, PlausibilityResult):
        nw = ref.not_observable_warning()
        if nw is not None:
            out.append(ResultWarning(nw.code, f"{r.window.names[0]}: {nw.message}", nw.evidence))
    else:
        out.append(ResultWarning("not_observable", f"{r.window.names[0]}: the star tracker could not be checked "
                                 f"against the gyro ({ref}): time_offset_s is null", {"parameters": ["time_offset_s"]}))
    c = r.constancy
    if c is not None and not c.constant:
        a = ARCSEC_PER_RAD
        out.append(ResultWarning(
            "bias_not_constant",
            f"the gyro offsets differ between the {c.parts} sub-intervals beyond their sigmas (chi² {c.chi2:.1f} "
            f"with {c.dof} degrees of freedom, p = {c.p_value:.2g}): the offsets drift within the window; the "
            f"reported sigma includes their spread (x {np.round(c.inflation, 1).tolist()}); fit shorter windows "
            "(sliding_window_s) to follow the drift",
            {"parts": c.parts, "chi2": c.chi2, "dof": c.dof, "p_value": c.p_value, "alpha": c.alpha,
             "inflation": [float(x) for x in c.inflation],
             "between_sigma_sensor_arcsec_s": [float(x) for x in c.between_sigma_rad_s * a],
             "subinterval_delta_sensor_arcsec_s": [[float(x) for x in row] for row in c.estimates * a],
             "subinterval_delta_sigma_sensor_arcsec_s": [[float(x) for x in row] for row in c.sigmas * a]},
        ))
    fit = r.fit
    if float(np.max(fit.residual_consistency)) > RESIDUAL_CONSISTENCY_MAX and not _causes(out):
        rms = fit.residual_rms_rad * ARCSEC_PER_RAD
        out.append(ResultWarning(
            "implausible_input",
            f"the fit's residuals {np.round(rms[0], 1).tolist()} arcsec rms are "
            f"{np.round(np.sqrt(fit.residual_consistency[0]), 1).tolist()} times what the star-tracker and gyro "
            "noise explain, and neither the convention check, the time offset nor the offsets' constancy names a "
            "cause: check the mountings and the gyro data",
            {"residual_rms_arcsec": [[float(x) for x in row] for row in rms],
             "residual_consistency": [[float(x) for x in row] for row in fit.residual_consistency],
             "consistency_max": RESIDUAL_CONSISTENCY_MAX},
        ))
    return out


# ---------------------------------------------------------------------------------------------------
# Report: summary and tables.


def subinterval_rows(r: Outcome) -> list[dict[str, Any]]:
    epoch, q_BG, arcsec = r.window.epoch, r.window.q_BG, ARCSEC_PER_RAD
    rows = []
    for (a, e), fit_k, (kind, parts, index) in zip(r.edges, r.subs, r.kinds, strict=True):
        start_ns, end_ns = epoch + int(round(a * NS_PER_S)), epoch + int(round(e * NS_PER_S))
        row: dict[str, Any] = {
            "kind": kind, "parts": parts, "index": index,
            "start": iso(start_ns), "end": iso(end_ns), "start_tai_ns": start_ns, "end_tai_ns": end_ns,
        }
        if fit_k is None:
            row.update(n_samples=0, gyro_bias_rad_s=None, gyro_bias_sigma_rad_s=None)
        else:
            bk, bk_sig = bias_body(fit_k, q_BG, fit_k.covariance[3:6, 3:6])
            _, bk_sig_p = bias_body(fit_k, q_BG, fit_k.covariance_paper[3:6, 3:6])
            row.update(
                n_samples=int(fit_k.n_samples.sum()),
                gyro_bias_rad_s=as_floats(bk),
                gyro_bias_sigma_rad_s=as_floats(bk_sig),
                gyro_bias_sigma_paper_rad_s=as_floats(bk_sig_p),
                delta_sensor_arcsec_s=as_floats(fit_k.delta_R_rad_s * arcsec),
                delta_sensor_sigma_arcsec_s=as_floats(fit_k.sigma[3:6] * arcsec),
                delta_sensor_sigma_paper_arcsec_s=as_floats(fit_k.sigma_paper[3:6] * arcsec),
                residual_rms_arcsec=as_floats(fit_k.residual_rms_rad[0] * arcsec),
                converged=bool(fit_k.converged),
            )
        rows.append(row)
    return rows


def _mounting(fit: GyroBiasFit, q_BR: NDArray[np.float64]) -> dict[str, Any] | None:
    if fit.mounting is None:
        return None
    m = fit.mounting
    return {
        "determinable": bool(m.determinable),
        "reason": m.reason,
        "misalignment_sensor_rad": None if m.rotvec_R_rad is None else as_floats(m.rotvec_R_rad),
        "misalignment_sigma_sensor_rad": as_floats(m.sigma_rad),
        "misalignment_sigma_paper_sensor_rad": as_floats(m.sigma_paper_rad),
        "q_BS": None if m.rotvec_R_rad is None else as_floats(rotations.quat_canonical(q_BR)),
        "condition_number": float(m.condition_number),
        "max_abs_correlation": float(m.max_abs_correlation),
        "correlation": [as_floats(r) for r in m.correlation],
    }


def fit_summary(r: Outcome, sub_rows: list[dict[str, Any]], warnings: list[ResultWarning]) -> dict[str, Any]:
    fit, win, params, arcsec = r.fit, r.window, r.params, ARCSEC_PER_RAD
    cov_delta = r.delta_covariance
    b, b_sig = bias_body(fit, win.q_BG, cov_delta)
    _, b_sig_constant = bias_body(fit, win.q_BG, fit.covariance[3:6, 3:6])
    _, b_sig_paper = bias_body(fit, win.q_BG, fit.covariance_paper[3:6, 3:6])
    covariance = fit.covariance.copy()
    covariance[3:6, 3:6] = cov_delta
    q_BR = rotations.quat_multiply(win.q_BG, rotations.quat_conjugate(fit.q_RG))
    q_IB0 = rotations.quat_canonical(rotations.quat_multiply(fit.q_IR0, rotations.quat_conjugate(q_BR)))
    t0_ns = win.epoch + int(round(fit.t0_s * NS_PER_S))
    status = fit.status
    if not fit.converged and float(np.max(fit.residual_consistency)) > RESIDUAL_CONSISTENCY_MAX and _causes(warnings):
        status += f"; likely cause: {', '.join(_causes(warnings))} (see the warnings)"
    found = r.plausibility.get(win.names[0])
    ref = found if isinstance(found, PlausibilityResult) else None
    sensors = {
        name: {
            "n_samples": int(fit.n_samples[j]),
            "residual_rms_arcsec": as_floats(fit.residual_rms_rad[j] * arcsec),
            "residual_rms_gyro_arcsec": as_floats(fit.residual_rms_gyro_rad[j] * arcsec),
            "star_tracker_sigma_arcsec": as_floats(fit.star_tracker_sigma_rad[j] * arcsec),
            "residual_consistency": as_floats(fit.residual_consistency[j]),
            "plausibility": (res.summary() if isinstance(res := r.plausibility.get(name), PlausibilityResult)
                             else {"error": res}),
        }
        for j, name in enumerate(win.names)
    }
    c = r.constancy
    return {
        "gyro_bias_rad_s": as_floats(b),
        "gyro_bias_sigma_rad_s": as_floats(b_sig),
        "gyro_bias_sigma_constant_rad_s": as_floats(b_sig_constant),
        "gyro_bias_sigma_paper_rad_s": as_floats(b_sig_paper),
        "delta_sensor_arcsec_s": as_floats(fit.delta_R_rad_s * arcsec),
        "delta_sensor_sigma_arcsec_s": as_floats(np.sqrt(np.diag(cov_delta)) * arcsec),
        "delta_sensor_sigma_paper_arcsec_s": as_floats(fit.sigma_paper[3:6] * arcsec),
        "delta_body_arcsec_s": as_floats(-b * arcsec),
        "delta_body_sigma_arcsec_s": as_floats(b_sig * arcsec),
        "offset_constancy": None if c is None else {
            "parts": c.parts, "chi2": float(c.chi2), "dof": c.dof, "p_value": float(c.p_value), "alpha": c.alpha,
            "constant": bool(c.constant), "inflation": as_floats(c.inflation),
            "between_sigma_sensor_arcsec_s": as_floats(c.between_sigma_rad_s * arcsec)},
        "time_offset_s": None if ref is None else ref.time_offset_s,
        "time_offset_sigma_s": None if ref is None else ref.time_offset_sigma_s,
        "time_offset_observable": False if ref is None else bool(ref.time_offset_observable),
        "time_offset_corrected_s": r.time_offset_applied_s,
        "quaternion_convention": None if ref is None else ref.convention,
        "initial_mrp": as_floats(fit.initial_mrp),
        "initial_mrp_sigma": as_floats(fit.sigma[:3]),
        "initial_mrp_sigma_paper": as_floats(fit.sigma_paper[:3]),
        "initial_time": iso(t0_ns),
        "initial_time_tai_ns": t0_ns,
        "initial_q_IS": as_floats(fit.q_IR0),
        "initial_q_IB": as_floats(q_IB0),
        "sigma_unit_weight": float(fit.sigma_unit_weight),
        "residual_rms_arcsec": as_floats(fit.residual_rms_rad[0] * arcsec),
        "residual_rms_gyro_arcsec": as_floats(fit.residual_rms_gyro_rad[0] * arcsec),
        "residual_consistency": as_floats(fit.residual_consistency[0]),
        "star_tracker_sigma_arcsec": as_floats(fit.star_tracker_sigma_rad[0] * arcsec),
        "iterations": int(fit.iterations),
        "converged": bool(fit.converged),
        "status": status,
        "scheme": int(params.scheme),
        "use_smoothed_rates": bool(params.use_smoothed_rates),
        "smoothing_harmonics": r.harmonics,
        "weights": as_floats(params.weights),
        "gyro_arw_rad_sqrt_s": as_floats(r.arw),
        "gyro_arw_source": r.arw_source,
        "reference_sensor": win.names[0],
        "sensors": sensors,
        "n_star_tracker_samples": int(fit.n_samples.sum()),
        "n_gyro_samples": int(win.t_g_ns.size),
        "parameter_names": list(fit.parameter_names),
        "covariance": [as_floats(row) for row in covariance],
        "covariance_paper": [as_floats(row) for row in fit.covariance_paper],
        "condition_number": float(fit.condition_number),
        "mounting": _mounting(fit, q_BR),
        "subintervals": sub_rows,
    }


def series_tables(r: Outcome) -> dict[str, dict[str, NDArray[Any]]]:
    """Residual rotations per star-tracker sample and the body rates (every k-th gyro sample)."""
    fit, win, arcsec = r.fit, r.window, ARCSEC_PER_RAD
    b, _ = bias_body(fit, win.q_BG, fit.covariance[3:6, 3:6])
    residuals = {
        "time_tai_ns": win.t_st_ns,
        "sensor": np.asarray(win.sensor_of, dtype=object),
        **{f"e{i + 1}_arcsec": fit.residuals_rad[:, i] * arcsec for i in range(3)},
    }
    stride = max(1, -(-win.t_g_ns.size // RATES_TABLE_MAX_ROWS))
    r_bg = rotations.quat_to_dcm(win.q_BG)
    w_B = (win.w_G[::stride] @ r_bg.T - b) / RAD_PER_DEG
    rates: dict[str, NDArray[Any]] = {"time_tai_ns": win.t_g_ns[::stride]}
    rates.update({f"w{i + 1}_B_deg_s": w_B[:, i] for i in range(3)})
    if r.w_ap is not None:
        w_ap_B = (r.w_ap[::stride] @ r_bg.T - b) / RAD_PER_DEG
        rates.update({f"w{i + 1}_B_ap_deg_s": w_ap_B[:, i] for i in range(3)})
    return {"residuals": residuals, "rates": rates}


def subinterval_table(sub_rows: list[dict[str, Any]]) -> dict[str, NDArray[Any]]:
    table: dict[str, NDArray[Any]] = {
        "kind": np.array([r["kind"] for r in sub_rows], dtype=object),
        "parts": np.array([r["parts"] for r in sub_rows], dtype=np.int64),
        "index": np.array([r["index"] for r in sub_rows], dtype=np.int64),
        "start_tai_ns": np.array([r["start_tai_ns"] for r in sub_rows], dtype=np.int64),
        "end_tai_ns": np.array([r["end_tai_ns"] for r in sub_rows], dtype=np.int64),
        "n_samples": np.array([r["n_samples"] for r in sub_rows], dtype=np.int64),
    }
    for key, col in (
        ("delta_sensor_arcsec_s", "delta{}_sensor_arcsec_s"),
        ("delta_sensor_sigma_arcsec_s", "delta{}_sensor_sigma_arcsec_s"),
        ("gyro_bias_rad_s", "gyro_bias{}_rad_s"),
        ("gyro_bias_sigma_rad_s", "gyro_bias{}_sigma_rad_s"),
        ("residual_rms_arcsec", "residual_rms{}_arcsec"),
    ):
        vals = np.array([r.get(key) or [np.nan] * 3 for r in sub_rows], dtype=np.float64).reshape(-1, 3)
        table.update({col.format(i + 1): vals[:, i] for i in range(3)})
    return table


def combine_segments(params: Params, segments: list[tuple[int, int]],
                     results: list[tuple[tuple[int, int], TaskResult]], notes: list[str]) -> TaskResult:
    """The per-segment results of an arc split at its gyro gaps as one (see
    :func:`app.jobs.types.gyro_bias_fit._run_segments`): offsets combined by inverse variance per body axis,
    their agreement tested by chi-square (beyond p = 0.01 the sigma inflated by sqrt(chi2 / dof))."""
    from processing.estimation.chi2 import chi2_sf

    bias = np.array([r.summary["gyro_bias_rad_s"] for _, r in results], dtype=float)
    sig = np.array([r.summary["gyro_bias_sigma_rad_s"] for _, r in results], dtype=float)
    w = 1.0 / sig ** 2
    comb = np.sum(w * bias, axis=0) / np.sum(w, axis=0)
    comb_sig = 1.0 / np.sqrt(np.sum(w, axis=0))
    dof = 3 * (len(results) - 1)
    chi2 = float(np.sum((bias - comb) ** 2 * w))
    p = float(chi2_sf(chi2, dof)) if dof else 1.0
    consistent = p >= 0.01
    inflation = 1.0 if consistent else float(np.sqrt(chi2 / dof))
    longest = max(range(len(results)), key=lambda i: results[i][0][1] - results[i][0][0])
    base = results[longest][1]
    rows = [{"index": i, "start": iso(a), "end": iso(e), "start_tai_ns": a, "end_tai_ns": e,
             "duration_s": (e - a) / NS_PER_S, "n_star_tracker_samples": r.summary["n_star_tracker_samples"],
             "n_gyro_samples": r.summary["n_gyro_samples"], "gyro_bias_rad_s": r.summary["gyro_bias_rad_s"],
             "gyro_bias_sigma_rad_s": r.summary["gyro_bias_sigma_rad_s"], "converged": r.summary["converged"],
             "residual_rms_arcsec": r.summary["residual_rms_arcsec"]} for i, ((a, e), r) in enumerate(results)]
    summary = dict(base.summary)
    summary.update(
        gyro_bias_rad_s=as_floats(comb), gyro_bias_sigma_rad_s=as_floats(comb_sig * inflation),
        delta_body_arcsec_s=as_floats(-comb * ARCSEC_PER_RAD),
        delta_body_sigma_arcsec_s=as_floats(comb_sig * inflation * ARCSEC_PER_RAD),
        segments=rows,
        combined={"n_segments": len(results), "chi2": chi2, "dof": dof, "p_value": p, "consistent": consistent,
                  "inflation": inflation, "gyro_bias_rad_s": as_floats(comb),
                  "gyro_bias_sigma_rad_s": as_floats(comb_sig * inflation),
                  "detail_segment": longest,
                  "note": "gyro_bias_* are combined over the segments; the other figures (attitude, residuals, "
                          "sub-intervals, tables) are those of the longest segment, detail_segment"},
        converged=all(r.summary["converged"] for _, r in results),
    )
    warnings: list[ResultWarning] = []
    seen: set[tuple[str, str]] = set()
    for i, (_, r) in enumerate(results):
        for wng in r.warnings:
            key = (wng.code, wng.message)
            if key not in seen:
                seen.add(key)
                warnings.append(ResultWarning(wng.code, f"segment {i}: {wng.message}", {**wng.evidence, "segment": i}))
    if not consistent:
        warnings.append(ResultWarning(
            "bias_not_constant",
            f"the gyro offsets of the {len(results)} segments between the gyro gaps differ beyond their sigmas "
            f"(chi² {chi2:.1f} with {dof} degrees of freedom, p = {p:.2g}): the combined sigma is inflated by "
            f"{inflation:.2f}; see the segments' own offsets",
            {"chi2": chi2, "dof": dof, "p_value": p, "inflation": inflation}))
    notes.insert(0, f"the window was split at {len(segments) - 1} gyro gap(s) longer than max_gyro_gap_s = "
                    f"{params.max_gyro_gap_s:g} s into {len(segments)} segments; {len(results)} fitted, offsets "
                    "combined by inverse variance")
    tables = dict(base.tables)
    tables["segments"] = {
        "time_tai_ns": np.array([r["start_tai_ns"] for r in rows], dtype=np.int64),
        "end_tai_ns": np.array([r["end_tai_ns"] for r in rows], dtype=np.int64),
        **{f"gyro_bias{i + 1}_rad_s": bias[:, i] for i in range(3)},
        **{f"gyro_bias{i + 1}_sigma_rad_s": sig[:, i] for i in range(3)}}
    return TaskResult(summary=summary, tables=tables, notes=notes + list(base.notes), files=dict(base.files),
                      warnings=warnings)
