"""JSON-able summary and segment table of an orbital-attitude result (processing.star_tracker.orbital_attitude).

Split from processing.star_tracker.orbital_attitude (the 003 §1.6 computation): :func:`summary_of` (GNSS fit
and its check, smoothing, coverage, angle sigmas), :func:`gnss_check_summary` and :func:`segment_table`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from processing.orbits.gnss_checks import GNSS_RMS_RATIO_MAX, GnssFitCheck
from processing.star_tracker.orbital_attitude import EULER_SEQUENCES, OrbitalAttitude
from processing.units import ARCSEC_PER_RAD

SUMMARY_LIST_MAX = 10
"""Lists in the summary keep their first entries (the tables have all)."""


def gnss_check_summary(c: GnssFitCheck) -> dict[str, Any]:
    """JSON-able figures of a GNSS fit check."""
    return {"consistent": c.consistent, "position_sigma_m": c.position_sigma_m,
            "velocity_sigma_m_s": c.velocity_sigma_m_s, "noise_source": c.noise_source,
            "rms_ratio": {"position": c.rms_ratio[0], "velocity": c.rms_ratio[1]}, "ratio_max": GNSS_RMS_RATIO_MAX,
            "chi2": c.chi2, "dof": c.dof, "p_value": c.p_value, "n_late_tags": int(c.late_tags.sum()),
            "late_tag_offset_s": c.late_offset_s, "inertial_velocity": c.inertial_velocity, "cause": c.cause,
            "position_error_m": c.position_error_m, "velocity_error_m_s": c.velocity_error_m_s}


def summary_of(result: OrbitalAttitude) -> dict[str, Any]:
    """JSON-able figures of a result besides the angle statistics: GNSS fit, smoothing, coverage (lists cut to
    their first SUMMARY_LIST_MAX entries with their counts; :func:`segment_table` has every segment)."""
    arcsec = ARCSEC_PER_RAD
    seg = [s for s in result.segments if s.smoothed]
    w = np.array([s.stop - s.start for s in seg], dtype=float)
    resid = (np.sqrt(np.sum(w[:, None] * np.stack([s.residual_rms_rad for s in seg]) ** 2, axis=0) / np.sum(w))
             * arcsec).tolist() if seg else None
    names = ("pitch", "yaw", "roll")
    frame_sig = result.orbit_frame_sigma_rad
    att_sig = result.attitude_sigma_rad
    out: dict[str, Any] = {
        "n_samples": int(result.time_tai_ns.size),
        "n_dropped_outside_gnss": int(result.dropped_tai_ns.size),
        "euler_sequence": result.euler_sequence,
        "euler_sequence_description": EULER_SEQUENCES[result.euler_sequence],
        "gnss_fit": {
            "method": result.gnss.method,
            "n_samples": result.gnss.n_samples,
            "n_arcs": len(result.gnss.arcs),
            "position_residual_rms_m": result.gnss.position_rms_m.tolist(),
            "velocity_residual_rms_m_s": result.gnss.velocity_rms_m_s.tolist(),
            "degree": [a.degree for a in result.gnss.arcs][:SUMMARY_LIST_MAX] if result.gnss.method == "chebyshev"
            else None,
            "harmonics": [list(a.harmonics) for a in result.gnss.arcs][:SUMMARY_LIST_MAX]
            if result.gnss.method == "sine" else None,
            "check": None if result.gnss_check is None else gnss_check_summary(result.gnss_check),
            "n_dropped_late_tags": result.gnss_dropped_late,
            "check_after_dropping": None if result.gnss_recheck is None else gnss_check_summary(result.gnss_recheck),
        },
        "orbit_frame_sigma_arcsec": None if frame_sig is None else
        {n: float(x * arcsec) for n, x in zip(names, frame_sig, strict=True)},
        "angle_sigma_arcsec": None if frame_sig is None else
        {n: float(np.hypot(x, 0.0 if att_sig is None else att_sig[i]) * arcsec)
         for i, (n, x) in enumerate(zip(names, frame_sig, strict=True))},
        "angle_sigma_note": ("orbit-frame error from the GNSS fit combined with the smoothed star-tracker error"
                             if att_sig is not None else "orbit-frame error from the GNSS fit only (no smoothing: "
                             "add the star-tracker noise of each sample)"),
        "manoeuvres": {"n": len(result.manoeuvres_tai_ns), "segmented": bool(result.manoeuvres_tai_ns),
                       "intervals_tai_ns": [list(m) for m in result.manoeuvres_tai_ns][:SUMMARY_LIST_MAX]},
        "n_smoothing_segments": len(result.segments),
        "smoothing_segments": [{"start_tai_ns": int(result.time_tai_ns[s.start]),
                                "end_tai_ns": int(result.time_tai_ns[s.stop - 1]),
                                "n_samples": s.stop - s.start, "harmonics": list(s.harmonics),
                                "residual_rms_arcsec": (s.residual_rms_rad * arcsec).tolist()}
                               for s in result.segments[:SUMMARY_LIST_MAX]],
        "smoothing_residual_rms_arcsec": resid,
        "n_ascending_nodes": int(result.ascending_nodes_tai_ns.size),
        "ascending_nodes_tai_ns": [int(x) for x in result.ascending_nodes_tai_ns[:SUMMARY_LIST_MAX]],
    }
    return out


def segment_table(result: OrbitalAttitude) -> dict[str, NDArray]:
    """Every smoothing segment: start/end times, samples, harmonics and residual rms per sensor axis."""
    segs = result.segments
    t = result.time_tai_ns
    res = np.array([s.residual_rms_rad for s in segs]).reshape(-1, 3) * ARCSEC_PER_RAD
    h = np.array([s.harmonics for s in segs], dtype=np.int64).reshape(-1, 3)
    man = np.zeros(len(segs), dtype=bool)
    for a, b in result.manoeuvres_tai_ns:
        man |= np.array([(t[s.start] >= a) & (t[s.stop - 1] <= b) for s in segs], dtype=bool)
    return {"time_tai_ns": np.array([t[s.start] for s in segs], dtype=np.int64),
            "end_tai_ns": np.array([t[s.stop - 1] for s in segs], dtype=np.int64),
            "n_samples": np.array([s.stop - s.start for s in segs], dtype=np.int64),
            "in_manoeuvre": man,
            **{f"harmonics_z{i + 1}": h[:, i] for i in range(3)},
            **{f"residual_rms_x{i + 1}_arcsec": res[:, i] for i in range(3)}}
