"""Job ``alignment_calibration``: its figures, in the spirit of 000 figs. 5-8 (drift, attitude errors, rate
errors and a fragment, rate coverage), drawn from the result's tables and summary."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from processing.tasks import TaskResult
from processing.units import NS_PER_S, RAD_PER_ARCSEC

if TYPE_CHECKING:
    from app.jobs.types.alignment_calibration import Params


_COLOURS = ("tab:blue", "tab:green", "tab:red")


def _shade_predicted(ax: Any, t: NDArray[np.float64], mode: NDArray[Any]) -> None:
    pred = mode == "predicted"
    if not np.any(pred):
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], pred.astype(int), [0]])))
    for a, b in zip(edges[0::2], edges[1::2], strict=True):
        ax.axvspan(t[a], t[min(b, t.size - 1)], color="0.9", lw=0)


def _fig_drift(result: TaskResult) -> Figure:
    tab = result.tables["drift"]
    t0 = int(tab["time_tai_ns"][0])
    t = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    fig = Figure(figsize=(9, 4.5), label="Gyro drift estimate (000 fig. 5)")
    ax = fig.add_subplot()
    _shade_predicted(ax, t, np.asarray(tab["mode"]))
    for i, a in enumerate("xyz"):
        ax.plot(t, tab[f"drift_{a}_arcsec_s"], color=_COLOURS[i], lw=0.8, label=f"b_{a}")
        ax.plot(t, tab[f"model_{a}_arcsec_s"], color=_COLOURS[i], lw=1.5, ls="--")
    end = [v / RAD_PER_ARCSEC for v in result.summary["apparent_drift_rad_s"] if v is not None]
    lo = (min(end) if end else -1.0) - 0.5
    hi = (max(end) if end else 1.0) + 0.5
    ax.set_ylim(lo, hi)
    ax.set_xlabel("time since the first sample [s]")
    ax.set_ylabel("drift [arcsec/s] (gyro frame)")
    conv = result.summary.get("drift_convergence_s")
    if conv is not None:
        ax.axvline(conv, color="k", lw=0.8, ls=":")
    ax.set_title("Drift estimate b^ (solid), trend (dashed); grey: slews, drift predicted")
    ax.legend(loc="upper right", ncols=3, fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _fig_attitude(result: TaskResult) -> Figure:
    tab = result.tables["attitude_residuals"]
    t0 = int(tab["time_tai_ns"][0])
    t = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    mode = np.asarray(tab["mode"])
    fig = Figure(figsize=(9, 4.5), label="Attitude residuals against the star tracker (000 fig. 6)")
    ax = fig.add_subplot()
    _shade_predicted(ax, t, mode)
    corr = mode == "corrected"
    for i, a in enumerate("xyz"):
        y = np.where(corr, np.asarray(tab[f"prior_{a}_arcsec"], dtype=float), np.nan)
        ax.plot(t, y, color=_COLOURS[i], lw=0.6, label=f"axis {a}")
    resumed = mode == "resumed"
    if np.any(resumed):
        mag = np.sqrt(sum(np.asarray(tab[f"prior_{a}_arcsec"], dtype=float) ** 2 for a in "xyz"))
        ax.plot(t[resumed], mag[resumed], "k^", ms=4, label="|error| at slew end")
    ax.set_xlabel("time since the first sample [s]")
    ax.set_ylabel("star tracker - prediction [arcsec]")
    ax.set_title("Attitude residuals (star-tracker axes); grey: slews without correction")
    ax.legend(loc="upper right", ncols=4, fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _fig_rates(result: TaskResult) -> Figure:
    tab = result.tables["rate_residuals"]
    fig = Figure(figsize=(9, 6.5), label="Rate residuals gyro - star tracker (000 figs. 7-8)")
    if len(tab["time_tai_ns"]) == 0:
        return fig
    t0 = int(tab["time_tai_ns"][0])
    t = (np.asarray(tab["time_tai_ns"]) - t0) / NS_PER_S
    ax1, ax2 = fig.subplots(2, 1)
    for i, a in enumerate("xyz"):
        ax1.plot(t, tab[f"residual_{a}_arcsec_s"], ".", ms=1, color=_COLOURS[i], label=f"axis {a}")
    ax1.set_ylabel("w_g - w_a [arcsec/s]")
    ax1.set_title("Calibrated gyro rate minus star-tracker rate in the alignment windows (star-tracker axes)")
    ax1.legend(loc="upper right", ncols=3, fontsize=8, markerscale=6)
    ax1.grid(alpha=0.3)
    first = t <= t[0] + 60.0  # a fragment, like 000 fig. 8; lines broken between windows
    tf = t[first]
    gap = np.concatenate([np.diff(tf) > 1.0, [False]])
    for i, a in enumerate("xyz"):
        y = np.asarray(tab[f"residual_{a}_arcsec_s"], dtype=float)[first]
        ax2.plot(np.insert(tf, np.flatnonzero(gap) + 1, np.nan), np.insert(y, np.flatnonzero(gap) + 1, np.nan), "-",
                 lw=0.8, color=_COLOURS[i])
    ax2.set_xlabel("time since the first window sample [s]")
    ax2.set_ylabel("w_g - w_a [arcsec/s]")
    ax2.set_title("Fragment: the first minute")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _fig_coverage(result: TaskResult) -> Figure:
    tab = result.tables["rate_coverage"]
    fig = Figure(figsize=(7, 5.5), label="Rate-direction coverage of the alignment windows")
    ax = fig.add_subplot()
    x, y, z = (np.asarray(tab[f"direction_{a}"], dtype=float) for a in "xyz")
    lon = np.degrees(np.arctan2(y, x))
    lat = np.degrees(np.arcsin(np.clip(z, -1.0, 1.0)))
    used = np.asarray(tab["used"], dtype=bool)
    sc = ax.scatter(lon[used], lat[used], c=np.asarray(tab["mean_rate_deg_s"], dtype=float)[used], cmap="viridis",
                    s=18)
    anti_lon = np.where(lon[used] > 0, lon[used] - 180.0, lon[used] + 180.0)  # -w: the same rotation axis
    ax.scatter(anti_lon, -lat[used], facecolors="none", edgecolors="0.6", s=18)
    if np.any(~used):
        ax.scatter(lon[~used], lat[~used], marker="x", color="tab:red", s=18, label="rejected (fit residual)")
        ax.legend(loc="lower right", fontsize=8)
    fig.colorbar(sc, ax=ax, label="mean |w| in the window [deg/s]")
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_xlabel("azimuth of w in star-tracker axes (atan2(y, x)) [deg]")
    ax.set_ylabel("elevation above the x-y plane [deg]")
    ev = result.summary["rate_spread_eigenvalues"]
    obs = result.summary["misalignment_observable"]
    ax.set_title(f"Rate directions; spread eigenvalues {', '.join(f'{v:.2f}' for v in ev)}; observable {obs}",
                 fontsize=9)
    ax.grid(alpha=0.3)
    return fig


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    return {
        "drift": _fig_drift(result),
        "attitude_residuals": _fig_attitude(result),
        "rate_residuals": _fig_rates(result),
        "rate_coverage": _fig_coverage(result),
    }

