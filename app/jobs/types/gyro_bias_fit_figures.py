"""Figures of the job ``gyro_bias_fit`` (003 figs. 13-16), drawn from the job's tables and summary."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from app.services.times import iso
from processing.tasks import TaskResult
from processing.units import DEG_H_PER_RAD_S, NS_PER_S


def figures(result: TaskResult, params: Any) -> dict[str, Figure]:
    """Rates with their approximation (fig. 13a), residual rotations per sensor axis (figs. 13b-c, 14),
    offsets per sub-interval (the numbers of figs. 15-16)."""
    figs: dict[str, Figure] = {}
    summary = result.summary
    res = result.tables["residuals"]
    t_ref = int(np.min(res["time_tai_ns"]))

    def seconds(t_ns: NDArray[Any]) -> NDArray[np.float64]:
        return (np.asarray(t_ns, dtype=np.int64) - t_ref).astype(np.float64) / NS_PER_S

    start = iso(t_ref)
    rates = result.tables["rates"]
    fig = Figure(figsize=(8, 7), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for i, ax in enumerate(axes):
        ax.plot(seconds(rates["time_tai_ns"]), rates[f"w{i + 1}_B_deg_s"], lw=0.4, color="0.6", label="gyro - bias")
        if f"w{i + 1}_B_ap_deg_s" in rates:
            ax.plot(seconds(rates["time_tai_ns"]), rates[f"w{i + 1}_B_ap_deg_s"], lw=1.2, color="C0", label="omega_ap")
        ax.set_ylabel(f"w{i + 1}, deg/s")
    axes[0].legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel(f"t, s from {start}")
    fig.suptitle("Body rates (003 fig. 13a), body axes y1 y2 y3")
    figs["rates"] = fig

    fig = Figure(figsize=(8, 7), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    ref = summary["reference_sensor"]
    sel = np.asarray(res["sensor"]) == ref
    rms = summary["residual_rms_arcsec"]
    for i, ax in enumerate(axes):
        ax.plot(seconds(res["time_tai_ns"][sel]), res[f"e{i + 1}_arcsec"][sel], lw=0.8, marker=".", ms=2)
        for s in (-1, 1):
            ax.axhline(s * rms[i], color="C3", lw=0.8)
        ax.set_ylabel(f"e{i + 1}, arcsec")
        ax.set_title(f"rms {rms[i]:.2f}\" (gyro noise part {summary['residual_rms_gyro_arcsec'][i]:.2f}\")",
                     fontsize="small", loc="right")
    axes[-1].set_xlabel(f"t, s from {start}")
    fig.suptitle(f"Residual rotations, {ref} axes x1 x2 x3, scheme {summary['scheme']} (003 figs. 13b-c)")
    figs["residuals"] = fig

    sub = result.tables["subintervals"]
    fig = Figure(figsize=(8, 7), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    a, e = seconds(sub["start_tai_ns"]), seconds(sub["end_tai_ns"])
    t_end = float(seconds(res["time_tai_ns"]).max())
    to_deg_h = DEG_H_PER_RAD_S
    for i, ax in enumerate(axes):  # body axes and deg/h: the frame and unit of the summary and the specification
        d = summary["gyro_bias_rad_s"][i] * to_deg_h
        s = summary["gyro_bias_sigma_rad_s"][i] * to_deg_h
        ax.axhspan(d - 3 * s, d + 3 * s, color="0.85", label="whole segment ±3σ")
        ax.hlines(d, 0.0, t_end, color="k", lw=1.0)
        v = np.asarray(sub[f"gyro_bias{i + 1}_rad_s"], dtype=float) * to_deg_h
        sv = np.asarray(sub[f"gyro_bias{i + 1}_sigma_rad_s"], dtype=float) * to_deg_h
        ok = np.isfinite(v)
        ax.hlines(v[ok], a[ok], e[ok], color="C0", lw=2.0)
        ax.errorbar(0.5 * (a[ok] + e[ok]), v[ok], yerr=3 * sv[ok], fmt="none", ecolor="C0", capsize=3,
                    label="sub-interval ±3σ")
        ax.set_ylabel(f"b_{'xyz'[i]} (body), deg/h")
    axes[0].legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel(f"t, s from {start}")
    fig.suptitle("Gyro bias b per sub-interval, body axes x y z (w_meas = w + b), as in the specification\n"
                 f"(003 §2.4 figs. 15-16 show Δ = -b in {ref} sensor axes, arcsec/s: summary delta_sensor_arcsec_s)",
                 fontsize="medium")
    figs["subintervals"] = fig
    return figs
