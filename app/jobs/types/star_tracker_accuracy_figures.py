"""Figures of the job ``star_tracker_accuracy`` in the spirit of 003 figs. 1-5 (and the inter-boresight angle of
its multi-head mode), drawn from the job's tables and summary."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from app.jobs import multi_head
from processing.tasks import TaskResult
from processing.units import NS_PER_S

SPECTRUM_ZOOM_FACTOR = 4.0
"""Zoomed spectra span 0 .. this x the smoother's cutoff frequency (003 figs. 3-5, lower panels)."""




def _fmt(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def _t_min(t_ns: np.ndarray, t0: int) -> np.ndarray:
    return (np.asarray(t_ns, dtype=np.int64) - t0) / NS_PER_S / 60.0


def _fig_rodrigues(result: TaskResult) -> Figure:
    res = result.tables["residuals"]
    s = result.summary
    t0 = int(res["time_tai_ns"][0])
    tm = _t_min(res["time_tai_ns"], t0)
    fig = Figure(figsize=(9, 7), label="Rodrigues parameters of q_c^-1 o q_n and their sine-series fit (003 fig. 1a)")
    axes = fig.subplots(3, 1, sharex=True)
    for i, ax in enumerate(axes):
        for seg in np.unique(res["segment"]):
            m = res["segment"] == seg
            ax.plot(tm[m], res[f"z{i + 1}_fit"][m], color="tab:blue", lw=1.0)
        ax.plot(tm[::10], res[f"z{i + 1}"][::10], "o", ms=3, mfc="none", color="tab:red")
        ax.set_ylabel(f"z{i + 1}")
        ax.grid(alpha=0.3)
    axes[0].set_title(f"N = {s['n_samples']}, M = {s['harmonics']}: fit (line), every 10th sample (markers)")
    axes[-1].set_xlabel("time since first sample [min]")
    return fig


def _fig_residuals(result: TaskResult) -> Figure:
    res = result.tables["residuals"]
    s = result.summary
    tm = _t_min(res["time_tai_ns"], int(res["time_tai_ns"][0]))
    fig = Figure(figsize=(9, 7), label="Smoothing residuals about the sensor axes (003 fig. 1b)")
    axes = fig.subplots(3, 1, sharex=True)
    out_t = result.tables["outliers"]["time_tai_ns"] if "outliers" in result.tables else np.zeros(0, np.int64)
    ok = ~np.isin(res["time_tai_ns"], out_t)  # the outliers would set the scale: marked at the axis edge
    for i, ax in enumerate(axes):
        sig_raw, sig = s["sigma_smoothing_arcsec"][i], s["sigma_arcsec"][i]
        ax.plot(tm[ok], res[f"e{i + 1}_arcsec"][ok], lw=0.7, color="tab:gray", label="e (003 eq. 2)")
        if s["gyro_used"]:
            ax.plot(tm[ok], res[f"e{i + 1}_corrected_arcsec"][ok], lw=0.7, color="tab:blue",
                    label="real motion removed")
        if not ok.all():
            top = ax.get_ylim()[1]
            ax.plot(tm[~ok], np.full(int((~ok).sum()), top), "v", ms=5, color="tab:red",
                    label=f"outliers ({int((~ok).sum())}, left out)")
        for v, style in ((sig_raw, "-"), (sig, "--")):
            if v is not None:
                ax.axhline(v, color="tab:red", ls=style, lw=1)
                ax.axhline(-v, color="tab:red", ls=style, lw=1)
        ax.set_ylabel(f"e{i + 1} [arcsec]")
        ax.set_title(f"x{i + 1}: sigma_smoothing = {_fmt(sig_raw)}\", sigma = {_fmt(sig)}\"", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since first sample [min]")
    return fig


def _fig_rates(result: TaskResult) -> Figure:
    s = result.summary
    fig = Figure(figsize=(9, 7), label="Angular velocity from the star tracker and smoothed gyro rates (003 fig. 2)")
    axes = fig.subplots(3, 1, sharex=True)
    rates = result.tables["rates"]
    t0 = int(rates["time_tai_ns"][0])
    for i, ax in enumerate(axes):
        if "gyro_comparison" in result.tables:
            g = result.tables["gyro_comparison"]
            tg = _t_min(g["time_tai_ns"], t0)
            ax.plot(tg, g[f"w{i + 1}_B_gyro_arcsec_s"], color="tab:orange", lw=1.2,
                    label="gyro, smoothed, offset removed")
            ax.plot(tg, g[f"w{i + 1}_B_star_tracker_arcsec_s"], color="tab:blue", lw=0.8, label="star tracker")
            diff = s["gyro_rate_rms_diff_arcsec_s"][i]
            ax.set_title(f"y{i + 1}: rms difference {_fmt(diff)}\"/s "
                         f"(expected {_fmt(s['gyro_rate_rms_diff_expected_arcsec_s'][i])}\"/s)", fontsize=9)
        else:
            ax.plot(_t_min(rates["time_tai_ns"], t0), rates[f"w{i + 1}_B_arcsec_s"], color="tab:blue", lw=0.8,
                    label="star tracker")
        ax.set_ylabel(f"w{i + 1} [arcsec/s]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since first sample [min]")
    return fig


def _fig_spectra(result: TaskResult) -> Figure:
    s = result.summary
    fig = Figure(figsize=(10, 8), label="Amplitude spectra of the angular velocity (003 figs. 3-5)")
    axes = fig.subplots(3, 2)
    zoom = SPECTRUM_ZOOM_FACTOR * s["cutoff_hz"]
    st = result.tables["spectrum_star_tracker_rate"]
    gy = result.tables.get("spectrum_gyro")
    for i in range(3):
        full, zoomed = axes[i]
        if gy is not None:
            band = gy["freq_hz"] <= 0.5
            full.plot(gy["freq_hz"][band], gy[f"a{i + 1}_arcsec_s"][band], lw=0.7, color="tab:orange", label="gyro")
            zb = gy["freq_hz"] <= zoom
            zoomed.plot(gy["freq_hz"][zb], gy[f"a{i + 1}_arcsec_s"][zb], lw=1.0, color="tab:orange", label="gyro")
        sb = st["freq_hz"] <= zoom
        zoomed.plot(st["freq_hz"][sb], st[f"a{i + 1}_arcsec_s"][sb], lw=1.0, color="tab:blue", ls="--",
                    label="star tracker")
        zoomed.axvline(s["cutoff_hz"], color="gray", lw=0.8, ls=":")
        full.set_ylabel(f"A(f), w{i + 1} [arcsec/s]")
        for ax in (full, zoomed):
            ax.grid(alpha=0.3)
        for line in s["spectral_lines"]:
            if line["source"] == "gyro" and line["axis"] == f"y{i + 1}" and line["freq_hz"] <= 0.5:
                # the fitted amplitude can stand above the sampled spectrum (a line between two grid
                # frequencies): the frame grows to keep the mark and its label inside
                amplitude = line["amplitude_arcsec_s"]
                full.plot([line["freq_hz"]], [amplitude], marker="v", ms=4, color="tab:red", ls="none")
                full.set_ylim(top=max(full.get_ylim()[1], 1.3 * amplitude))
                full.annotate(f"{line['freq_hz']:.3f} Hz\n{amplitude:.2f}\"/s", (line["freq_hz"], amplitude),
                              fontsize=7)
    axes[0, 0].set_title("0 - 0.5 Hz")
    axes[0, 1].set_title(f"0 - {zoom:.3f} Hz (dotted: smoother cutoff)")
    axes[0, 1].legend(fontsize=8)
    axes[-1, 0].set_xlabel("frequency [Hz]")
    axes[-1, 1].set_xlabel("frequency [Hz]")
    return fig


def _fig_residual_spectrum(result: TaskResult) -> Figure:
    s = result.summary
    spec = result.tables["spectrum_star_tracker_residuals"]
    fig = Figure(figsize=(9, 6), label="Amplitude spectra of the star-tracker residuals, aliased lines marked")
    axes = fig.subplots(3, 1, sharex=True)
    aliases = sorted({round(x["aliased_freq_hz"], 5) for x in s["spectral_lines"] if x["source"] == "gyro"})
    for i, ax in enumerate(axes):
        ax.plot(spec["freq_hz"], spec[f"a{i + 1}_arcsec"], lw=0.8)
        for f in aliases:
            ax.axvline(f, color="tab:red", ls="--", lw=0.8)
        ax.axvline(s["cutoff_hz"], color="gray", lw=0.8, ls=":")
        ax.set_ylabel(f"A(f), e{i + 1} [arcsec]")
        ax.grid(alpha=0.3)
    axes[0].set_title("dashed: gyro lines aliased to the star-tracker sampling; dotted: smoother cutoff", fontsize=9)
    axes[-1].set_xlabel("frequency [Hz]")
    return fig


def figure_names(summary: Mapping[str, Any], rows: Mapping[str, int]) -> list[str]:
    """The names :func:`figures` gives (the inter-boresight angle with two heads' ``inter_head`` table)."""
    return ["rodrigues_fit", "residuals", "rates", "spectra", "residual_spectra",
            *(["inter_boresight_angle"] if "inter_head" in rows else [])]


def figures(result: TaskResult, params: Any) -> dict[str, Figure]:
    return {
        "rodrigues_fit": _fig_rodrigues(result),
        "residuals": _fig_residuals(result),
        "rates": _fig_rates(result),
        "spectra": _fig_spectra(result),
        "residual_spectra": _fig_residual_spectrum(result),
        **({"inter_boresight_angle": multi_head.figure(result.tables)} if "inter_head" in result.tables else {}),
    }
