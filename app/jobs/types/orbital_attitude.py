"""Job ``orbital_attitude``: pitch, yaw, roll relative to the orbital frame (003 §1.6).

Star-tracker quaternions (in the inertial frame the tracker reports) + mounting + GNSS ITRF states
(+ optional IERS EOP) -> attitude of the body relative to the orbital frame, its statistics, the
time series, the "virtual orbit" (time since the preceding ascending node) and the reconstructed body
attitude as a CCSDS AEM 2.0 (REF_FRAME_A = GCRF, REF_FRAME_B = SC_BODY_1, scalar last). The
numerics are processing/star_tracker/orbital_attitude.py.
"""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field

from app.jobs.registry import JobType, always
from app.reports.headline import Answer
from processing.formats.ccsds_adm import aem_segment, write_aem
from processing.frames.earth_orientation import EarthOrientation, FrameInputError
from processing.frames.eop import EopCoverageError, interpolate_eop
from processing.orbits.gnss_orbit import GnssFitError
from processing.star_tracker.orbital_attitude import (
    EULER_SEQUENCES,
    OrbitalAttitudeError,
    orbital_attitude,
)
from processing.star_tracker.orbital_attitude_summary import segment_table, summary_of
from processing.tasks import Progress, ResultWarning, TaskError, TaskInputs, TaskResult
from processing.units import NS_PER_S

EOP_KIND = "eop_finals2000a"
AEM_FILE = "body_attitude.aem"


class Params(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sensor: str | None = Field(None, description="star tracker (default: the only one in the data/configuration)")
    inertial_frame: Literal["GCRF", "EME2000", "MOD", "TOD", "TEME"] = Field(
        "GCRF", description="frame of the star-tracker quaternions as stored (the tracker's reference frame)")
    orbital_frame: Literal["orbital_003", "lvlh_004"] = Field(
        "orbital_003", description="orbital_003: axis 3 radial out, axis 2 orbit normal (003 §1.6); lvlh_004: "
                                   "X0 along velocity, Z0 to the Earth's centre (004)")
    smoothing: bool = Field(True, description="smooth the star-tracker attitude (003 §1.3) before the angles")
    smoothing_frame: Literal["orbital", "inertial"] = Field(
        "orbital", description="smooth the attitude relative to the orbital frame (default) or in inertial "
                               "space as 003 does")
    trend_degree: Literal[1, 3] = Field(3, description="polynomial trend under the sine series: 1 = 003 §1.3 "
                                                       "exactly, 3 = fewer harmonics (see the report)")
    harmonics: int | None = Field(None, ge=0, le=1000, description="sine-series harmonics (default: by GCV)")
    gnss_smoother: Literal["chebyshev", "sine"] = Field(
        "chebyshev", description="GNSS smoothing: joint position/velocity Chebyshev fit (default) or 003's "
                                 "sine series")
    segment_max_s: float = Field(1200.0, gt=60.0, le=7200.0, description="longest smoothing segment [s]")
    max_gap_s: float = Field(60.0, gt=0.0, le=3600.0, description="a longer star-tracker gap splits segments")
    euler_sequence: Literal["231", "321"] = Field(
        "231", description="Euler sequence of the reported angles: 231 = pitch, yaw, roll of 003 §1.6; 321 = yaw, "
                           "pitch, roll (the common LVLH convention)")
    segment_at_manoeuvres: bool = Field(
        True, description="detect manoeuvres (rate relative to the orbital frame beyond the data's normal motion) "
                          "and start and end smoothing segments there")
    gnss_position_sigma_m: float | None = Field(
        None, gt=0, description="GNSS receiver position noise (1 sigma per axis); default: estimated from the data")
    gnss_velocity_sigma_m_s: float | None = Field(
        None, gt=0, description="GNSS receiver velocity noise (1 sigma per axis); default: estimated from the data")
    drop_late_gnss_tags: bool = Field(
        True, description="when the GNSS fit is inconsistent and some states are a pure time shift (late tags), "
                          "fit the orbit again without them")
    write_aem: bool = Field(True, description="write the body attitude as a CCSDS AEM 2.0 file")
    aem_object_name: str = Field("UNKNOWN", max_length=100, pattern=r"^[^\n\r=]*$")
    aem_object_id: str = Field("UNKNOWN", max_length=100, pattern=r"^[^\n\r=]*$")


def _sensor(inputs: TaskInputs, wanted: str | None) -> str:
    present = inputs.sensors("star_tracker")
    if not present:
        raise TaskError("no star_tracker samples in the job window")
    if wanted is not None:
        if wanted not in present:
            raise TaskError(f"no star_tracker samples of sensor {wanted!r} in the window (present: "
                            f"{', '.join(present)})")
        return wanted
    if len(present) == 1:
        return present[0]
    raise TaskError(f"several star trackers in the window ({', '.join(present)}): give the sensor parameter")


def _eop(inputs: TaskInputs) -> tuple[Any, dict[str, Any]]:
    ref = inputs.reference.get(EOP_KIND)
    if ref is None:
        zero = EarthOrientation()
        return None, {"source": zero.source, "kind": None}
    source = f"IERS finals2000A data set {ref.name!r} ({ref.id})"
    columns = ref.columns

    def at(t: np.ndarray) -> EarthOrientation:
        try:
            return interpolate_eop(columns, t, source=source)
        except EopCoverageError as exc:
            raise TaskError(f"the EOP data set {ref.name!r} does not cover the job window: {exc}") from exc

    info = {"source": source, "kind": EOP_KIND, "data_set_id": ref.id, "name": ref.name,
            "details": dict(ref.details)}
    return at, info


def run(inputs: TaskInputs, params: Params, progress: Progress) -> TaskResult:
    sensor = _sensor(inputs, params.sensor)
    q_BS = inputs.spacecraft.star_tracker_mounting(sensor)
    st = inputs.star_tracker(sensor)
    if len(inputs.sensors("gnss")) > 1:
        raise TaskError("several GNSS receivers in the window; the job expects one")
    gnss = inputs.gnss()
    notes: list[str] = []
    eop, eop_info = _eop(inputs)
    try:
        res = orbital_attitude(
            st.time_tai_ns, st.q_IS, gnss.time_tai_ns, gnss.r_E_m, gnss.v_E_m_s, q_BS=q_BS,
            inertial_frame=params.inertial_frame, orbital_frame=params.orbital_frame, smoothing=params.smoothing,
            smoothing_frame=params.smoothing_frame, harmonics=params.harmonics, trend_degree=params.trend_degree,
            eop=eop, gnss_method=params.gnss_smoother, segment_max_s=params.segment_max_s,
            max_gap_s=params.max_gap_s, euler_sequence=params.euler_sequence,
            segment_at_manoeuvres=params.segment_at_manoeuvres, gnss_position_sigma_m=params.gnss_position_sigma_m,
            gnss_velocity_sigma_m_s=params.gnss_velocity_sigma_m_s, drop_late_gnss_tags=params.drop_late_gnss_tags,
            progress=lambda f, s: progress(0.05 + 0.8 * f, s))
    except (OrbitalAttitudeError, GnssFitError, FrameInputError) as exc:
        raise TaskError(str(exc)) from exc
    if res.dropped_tai_ns.size:
        notes.append(f"{res.dropped_tai_ns.size} star-tracker samples outside the GNSS arcs were not used")
    notes.append(f"Earth orientation: {eop_info['source']}")
    stats = res.angle_statistics_deg()
    raw = res.angle_statistics_deg(raw=True)
    summary: dict[str, Any] = {
        **stats,
        "inertial_frame": params.inertial_frame,
        "orbital_frame": params.orbital_frame,
        "eop": eop_info,
        "sensor": sensor,
        "q_BS": q_BS.tolist(),
        "smoothing": params.smoothing,
        "smoothing_frame": params.smoothing_frame if params.smoothing else None,
        "trend_degree": params.trend_degree if params.smoothing else None,
        "raw": raw,
        "angles_by_sequence": {seq: res.angle_statistics_deg(sequence=seq) for seq in EULER_SEQUENCES},
        "first_tai_ns": int(res.time_tai_ns[0]),
        "last_tai_ns": int(res.time_tai_ns[-1]),
        **summary_of(res),
    }
    deg = np.degrees
    tables = {
        "angles": {"time_tai_ns": res.time_tai_ns, "pitch_deg": deg(res.pitch_rad), "yaw_deg": deg(res.yaw_rad),
                   "roll_deg": deg(res.roll_rad)},
        "attitude_detail": {
            "time_tai_ns": res.time_tai_ns, "time_since_node_s": res.time_since_node_s,
            "pitch_raw_deg": deg(res.pitch_raw_rad), "yaw_raw_deg": deg(res.yaw_raw_rad),
            "roll_raw_deg": deg(res.roll_raw_rad),
            **{f"q_GB_{i}": res.q_GB[:, i] for i in range(4)}},
        "smoothing_segments": segment_table(res),
    }
    warnings = _warnings(res, summary)
    if res.manoeuvres_tai_ns:
        notes.append(f"{len(res.manoeuvres_tai_ns)} manoeuvre(s) found; smoothing segments start and end there"
                     if params.smoothing else f"{len(res.manoeuvres_tai_ns)} manoeuvre(s) found")
    files: dict[str, tuple[bytes, str]] = {}
    if params.write_aem:
        progress(0.88, "writing the CCSDS AEM")
        comments = (f"Body attitude reconstructed by the orbital_attitude job (paper 003 sec. 1.6) from star "
                    f"tracker {sensor} and its mounting q_BS.",
                    ("Source quaternions in GCRF" if params.inertial_frame == "GCRF" else
                     f"Source quaternions in {params.inertial_frame}, converted to GCRF (IAU 2006/2000A)")
                    + f"; smoothing {'on (' + params.smoothing_frame + ' frame)' if params.smoothing else 'off'}.",
                    f"Earth orientation: {eop_info['source']}.")
        seg = aem_segment(res.time_tai_ns, res.q_GB, object_name=params.aem_object_name,
                          object_id=params.aem_object_id, ref_frame_a="GCRF", ref_frame_b="SC_BODY_1",
                          time_system="UTC", comments=comments)
        text = write_aem([seg], originator="ATTITUDE-SERVICE", creation_date=dt.datetime.now(dt.UTC))
        files[AEM_FILE] = (text.encode(), "text/plain")
    return TaskResult(summary=summary, tables=tables, notes=notes, files=files, warnings=warnings)


def _warnings(res: Any, summary: dict[str, Any]) -> list[ResultWarning]:
    """The GNSS fit judged against the receiver noise: ``time_offset`` when late tags explain it (with the
    offset), ``implausible_input`` otherwise (naming what was tried), each with the attitude error it causes."""
    chk = res.gnss_check
    if chk is None or chk.consistent:
        return []
    sig = summary.get("orbit_frame_sigma_arcsec") or {}
    ev = {**summary["gnss_fit"]["check"], "orbit_frame_sigma_arcsec": sig,
          "n_dropped_late_tags": res.gnss_dropped_late}
    ratio = max(chk.rms_ratio)
    head = (f"the GNSS orbit fit's residuals are {ratio:.3g} x the receiver noise ({chk.noise_source}: "
            f"{chk.position_sigma_m:.3g} m, {chk.velocity_sigma_m_s:.3g} m/s); likely cause: {chk.cause}")
    if res.gnss_dropped_late:
        after = res.gnss_recheck
        tail = (f"; the orbit was fitted again without the {res.gnss_dropped_late} late states"
                + ("" if after is None or after.consistent else
                   f", still {max(after.rms_ratio):.3g} x the noise") +
                f"; the orbital frame's error is {max(sig.values(), default=0.0):.3g} arcsec (in angle_sigma_arcsec)")
    else:
        tail = (f"; the angles carry an orbital-frame error up to {max(sig.values(), default=0.0):.3g} arcsec "
                "(angle_sigma_arcsec): correct the GNSS data before trusting them")
    code = "time_offset" if chk.late_offset_s is not None else "implausible_input"
    return [ResultWarning(code, head + tail, ev)]


def _unwrap_deg(a: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap(np.radians(a)))


def figures(result: TaskResult, params: Params) -> dict[str, Figure]:
    ang = result.tables["angles"]
    det = result.tables["attitude_detail"]
    t0 = int(ang["time_tai_ns"][0])
    minutes = (np.asarray(ang["time_tai_ns"], dtype=np.int64) - t0) / NS_PER_S / 60.0
    names = (("pitch_deg", "pitch α"), ("yaw_deg", "yaw β"), ("roll_deg", "roll γ"))
    fig = Figure(figsize=(9, 7), label="Orbital attitude angles against time (003 fig. 11)")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, (key, label) in zip(axes, names, strict=True):
        raw_key = key.replace("_deg", "_raw_deg")
        if params.smoothing:
            ax.plot(minutes, _unwrap_deg(det[raw_key]), ".", ms=2, color="0.6", label="raw")
        ax.plot(minutes, _unwrap_deg(ang[key]), "-", lw=1.2, color="tab:blue",
                label="smoothed (003 §1.3)" if params.smoothing else "raw")
        ax.set_ylabel(f"{label} [deg]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time since the first sample [min]")
    fig.suptitle(f"Attitude relative to the {params.orbital_frame} frame, Euler sequence {params.euler_sequence}")

    fig2 = Figure(figsize=(9, 7), label="Virtual orbit: angles against time since the ascending node (003 fig. 12)")
    axes2 = fig2.subplots(3, 1, sharex=True)
    since = np.asarray(det["time_since_node_s"], dtype=float) / 60.0
    orbit_no = np.cumsum(np.concatenate([[0], np.diff(since) < 0]))  # a new orbit when the clock resets
    for ax, (key, label) in zip(axes2, names, strict=True):
        for k in np.unique(orbit_no):
            m = orbit_no == k
            ax.plot(since[m], _unwrap_deg(ang[key][m]), "-", lw=1.0, label=f"orbit {k + 1}")
        ax.set_ylabel(f"{label} [deg]")
        ax.grid(alpha=0.3)
    if len(np.unique(orbit_no)) > 1:
        axes2[0].legend(loc="best", fontsize=8)
    axes2[-1].set_xlabel("time since the preceding ascending node [min]")
    fig2.suptitle("Virtual orbit")
    return {"orbital_angles": fig, "virtual_orbit": fig2}


JOB = JobType(
    name="orbital_attitude", title="Attitude relative to the orbital frame", paper="003 §1.6", params=Params,
    run=run, streams=("star_tracker", "gnss"), figures=figures,
    figure_names=always("orbital_angles", "virtual_orbit"), reference=(EOP_KIND,),
    description="Pitch, yaw and roll of the body relative to the orbital frame (003 §1.6) from star-tracker "
                "quaternions, the mounting and GNSS states (smoothed), with Earth orientation from an uploaded "
                "IERS finals2000A data set or zero; statistics, time series, virtual orbit and a CCSDS AEM of the "
                "body attitude.",
    headline=tuple(Answer(f"{a}_deg.mean", f"Orbital {a}, mean over the window", sigma=f"{a}_deg.std",
                          sigma_label="std",
                          frame="body B in the orbital frame O ({orbital_frame}), Euler sequence {euler_sequence}",
                          judged_by=(f"{a}_deg.min", f"{a}_deg.max")) for a in ("pitch", "yaw", "roll")),
)
