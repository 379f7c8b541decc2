"""Screening of telemetry: the rejection criteria of 002 (eqs. 15-17) and generic checks.

Every sample of every screened stream gets a flag per criterion; a sample is accepted when no
criterion flags it. Nothing is deleted: the result maps each stream's rows (in the order given) to
the criteria that rejected them, and :func:`flags_table` lays them out with their reasons.

Criteria (``name``: what is tested; where the tolerance comes from):

GNSS (ITRF position/velocity):
- ``energy`` (002, eq. 15): |h - h_ref| <= k1 dh with h = v^2 - 2 mu / r of the inertial velocity
  (v_I = v_E + w x r_E) and the paper's dh = 2 (v dv + mu / r^2 dr), dr and dv the receiver's
  errors. With ``energy_model="j2"`` the J2_EARTH potential is included, h = v^2 - 2 mu/r (1 - J2_EARTH (R/r)^2
  P2(sin lat)), which is constant for an axisymmetric field, so a real orbit is not flagged by the
  +-1e5 m^2/s^2 twice-per-orbit oscillation of the two-body h. h_ref comes from an uploaded reference
  orbit when given (the paper's "external trajectory measurements of the control centre"), else
  from a robust linear fit of h over the window; the model error of the variant (higher harmonics,
  drag: ~300 m^2/s^2 for "j2") is added to dh.
- ``orbit_plane``: the angle between the orbit normal r x v_I and its running median over
  +-``plane_window_s``; catches cross-track velocity and position errors, which leave eq. 15
  unchanged. Tolerance k (dv / v + dr / r) plus the J2_EARTH wobble of the normal over half the window.
- ``kinematic``: consecutive positions against the trapezoid integral of the velocities,
  |r_k+1 - r_k - (v_k + v_k+1) dt / 2| <= k sqrt(2 dr^2 + dt^2 dv^2 / 2) + dt^3 |r'''| / 12 (the
  trapezoid's truncation error, with the jerk bound of :func:`jerk_bound_m_s3`); a sample is flagged
  when both its increments fail (a single failing increment flags the later sample as a step).
- ``velocity``: v against the slope of a local quadratic fitted to the (unflagged) positions over
  +-``velocity_half_window`` samples; catches velocity errors in any direction (radial ones change
  neither h nor the plane). Tolerance k sqrt(sigma_fit^2 + dv^2) plus the fit's bias from the orbit's
  jerk (both computed from the actual sampling, so sparse GNSS data get a wider tolerance).
Magnetometer (nT, magnetometer frame):
- ``field_magnitude`` (002, eq. 16): | |H_meas| - |H_model| | <= k2 (dH_instr + dH_model), the model
  (IGRF-14 by default) evaluated at the GNSS position interpolated from accepted GNSS samples.
Panel currents (A):
- ``panel_range``: -k3 dI <= I <= I_max + k3 dI.
- ``panel_eclipse`` (002, eq. 17 with the modelled current zero in the Earth's shadow): in umbra
  |I| <= k3 dI; in penumbra I <= nu I_max + k3 dI (nu: visible fraction of the solar disc).
- ``panel_sun_norm`` (002, eq. 17 without an attitude): in sunlight the currents of panels spanning
  three dimensions determine the sun vector s_B (I_i = I_max,i max(0, n_i . s)); a consistent set
  gives |s| = 1. Rows of the lit panels at an epoch with | |s| - 1 | > k3 dI sqrt(n_lit) / I_max
  are flagged (the criterion cannot tell which panel is wrong, so it flags the epoch's lit panels);
  judged only at epochs where every configured panel has a sample not already rejected as a spike.
GNSS visibility: ``visibility_occulted``: a tracked satellite hidden by the Earth (002, eq. 6).
Star tracker: ``quaternion_norm`` and ``quaternion_jump`` (the rotation between consecutive
quaternions against the gyro rates, or against ``max_rate_rad_s`` without a gyro).
Any stream: ``spike`` (Hampel test: distance to the running median of +-``spike_half_window``
samples above k times the robust scale of those distances), ``stuck`` (the same values repeated
``stuck_min_run`` times or more), ``time_grid`` (a duplicated time, or a sample both of whose
intervals are off the nominal sampling grid).

Pure and vectorised; models are injectable (:class:`Environment`). Layout: this module applies the
criteria (:func:`screen`) and the magnetometer, visibility and star-tracker ones; the GNSS criteria are in
processing.screening.gnss, the panel ones in processing.screening.panels, what they share (thresholds,
results, generic checks) in processing.screening.base and the building blocks in
processing.screening.tools. All are re-exported here.
"""


from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.screening.base import (
    KEY_COLUMNS,
    VECTOR_COLUMNS,
    Collector,
    Columns,
    Criterion,
    Environment,
    ScreeningParams,
    ScreeningResult,
    generic_checks,
    sensor_groups,
)
from processing.screening.gnss import GnssTrack, screen_gnss
from processing.screening.panels import pivot, screen_panels, sun_from_currents
from processing.screening.tools import (
    ScreeningError,
    attribute_increments,
    energy_h,
    energy_tolerance,
    hampel,
    hermite_state,
    inertial_velocity_E,
    jerk_bound_m_s3,
    local_velocity_fit,
    robust_polyfit,
    rolling_median,
    stuck,
    time_grid,
)
from processing.spacecraft import Spacecraft
from processing.tasks import Mapper, serial_map
from processing.units import NS_PER_S

__all__ = [  # the screening API, wherever it is defined (base, gnss, panels, tools)
    "KEY_COLUMNS", "VECTOR_COLUMNS", "Columns", "Criterion", "Environment", "GnssTrack", "ScreeningError",
    "ScreeningParams", "ScreeningResult", "attribute_increments", "energy_h", "energy_tolerance", "hampel",
    "hermite_state", "inertial_velocity_E", "jerk_bound_m_s3", "local_velocity_fit", "pivot", "robust_polyfit",
    "rolling_median", "screen", "stuck", "sun_from_currents", "time_grid",
]

_Interval = tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]
"""Star-tracker times (n,), quaternion_jump residual and tolerance per interval (n - 1,) [rad]."""


def _screen_magnetometer(col: Collector, cols: Columns, p: ScreeningParams, track: GnssTrack | None,
                         env: Environment, notes: list[str], findings: dict[str, Any] | None = None) -> None:
    for _sensor, rows in sensor_groups(cols):
        generic_checks(col, cols, "magnetometer", rows, p, findings=findings)
        if track is None:
            continue
        t = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        b = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in ("bx", "by", "bz")], axis=1)
        r_E, _ = track.at(t, p.max_interpolation_gap_s)
        ok = np.isfinite(r_E).all(axis=1)
        model = np.full(rows.size, np.nan)
        if np.any(ok):
            model[ok] = np.linalg.norm(env.field_E_nT(r_E[ok], t[ok]), axis=1)
        dev = np.abs(np.linalg.norm(b, axis=1) - model)
        th = p.k_field * (p.magnetometer_error_nT + p.field_model_error_nT)
        col.add("field_magnitude", rows, dev > th, dev, th, "nT", "002 eq. 16", ok)
    if track is None:
        notes.append("no accepted GNSS samples: magnetometer field_magnitude (eq. 16) not applied")


def _screen_visibility(col: Collector, cols: Columns, p: ScreeningParams, track: GnssTrack | None,
                       nav: Mapping[str, Any] | None, notes: list[str]) -> None:
    from processing.orbits.gnss_ephemeris import satellite_positions_E
    from processing.vector_attitude.antenna_axis import dcm_EO_002, earth_occulted, line_of_sight_O

    for _sensor, rows in sensor_groups(cols):
        t_all = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        epochs = np.unique(t_all)
        flagged, dev, _ = time_grid(epochs, p.time_grid_tolerance)
        ti = np.searchsorted(epochs, t_all)
        col.add("time_grid", rows, flagged[ti], dev[ti], p.time_grid_tolerance, "fraction of the sampling period",
                "generic")
        if nav is None or track is None:
            continue
        sats = np.array([f"{s}{int(n):02d}" for s, n in zip(np.asarray(cols["system"])[rows],
                                                            np.asarray(cols["prn"])[rows], strict=True)])
        visible = np.asarray(cols["visible"], dtype=bool)[rows]
        names = sorted(set(sats.tolist()))
        r_E, v_E = track.at(epochs, p.max_interpolation_gap_s)
        ok = np.isfinite(r_E).all(axis=1)
        if not np.any(ok):
            continue
        pos = satellite_positions_E(nav, epochs[ok], names)
        g = line_of_sight_O(pos.r_E, r_E[ok], dcm_EO_002(r_E[ok], v_E[ok]))
        occ = earth_occulted(g, np.linalg.norm(r_E[ok], axis=1), p.grazing_altitude_m)
        occ_full = np.zeros((epochs.size, len(names)), bool)
        occ_full[ok] = occ
        known = np.zeros((epochs.size, len(names)), bool)
        known[ok] = pos.valid
        si = np.searchsorted(np.array(names), sats)
        row_occ = occ_full[ti, si]
        row_known = known[ti, si]
        col.add("visibility_occulted", rows, visible & row_occ, row_occ.astype(float), 0.5, "", "002 eq. 6",
                row_known & visible)
    if nav is None:
        notes.append("no GNSS navigation data (reference kind rinex_nav): visibility_occulted not applied")


def _screen_star_tracker(col: Collector, cols: Columns, spacecraft: Spacecraft, gyro: Columns | None,
                         p: ScreeningParams, findings: dict[str, Any] | None = None,
                         intervals: list[_Interval] | None = None
                         ) -> None:
    """quaternion_norm and quaternion_jump; against the gyro (which needs the mountings: MissingMountingError
    for a tracker not in the configuration) when there are gyro rates, else against max_rate_rad_s."""
    for sensor, rows in sensor_groups(cols):
        q = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in ("q0", "q1", "q2", "q3")], axis=1)
        t = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        norm_dev = np.abs(np.linalg.norm(q, axis=1) - 1.0)
        col.add("quaternion_norm", rows, norm_dev > p.quaternion_norm_tolerance, norm_dev, p.quaternion_norm_tolerance,
                "", "generic")
        generic_checks(col, cols, "star_tracker", rows, p, spike=False, findings=findings)
        if rows.size < 2:
            continue
        qn = q / np.linalg.norm(q, axis=1, keepdims=True)
        dq = rotations.quat_multiply(rotations.quat_conjugate(qn[:-1]), qn[1:])  # in sensor frame S
        rot = rotations.quat_to_rotvec(dq)
        dt = np.diff(t) / NS_PER_S
        if gyro is not None and len(gyro.get("time_tai_ns", [])) >= 2:
            q_BS, q_BG = spacecraft.star_tracker_mounting(sensor), spacecraft.gyro_mounting()
            tg = np.asarray(gyro["time_tai_ns"], dtype=np.int64)
            order = np.argsort(tg)
            tg = tg[order]
            w_G = np.stack([np.asarray(gyro[c], dtype=np.float64)[order] for c in ("wx", "wy", "wz")], axis=1)
            w_S = rotations.quat_rotate(rotations.quat_multiply(rotations.quat_conjugate(q_BS), q_BG), w_G)
            # integral of w over each star-tracker interval by the trapezoid of the cumulative sum
            cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (w_S[1:] + w_S[:-1])
                                                               * (np.diff(tg) / NS_PER_S)[:, None], axis=0)])
            ang = np.stack([np.interp(t, tg, cum[:, i], left=np.nan, right=np.nan) for i in range(3)], axis=1)
            expected = np.diff(ang, axis=0)
            jump = np.linalg.norm(rot - expected, axis=1)
            tol = p.k_quaternion * (np.sqrt(2) * p.star_tracker_error_rad + p.gyro_rate_error_rad_s * dt)
            # where a gyro gap (> 3 gyro steps) spans the interval the interpolated angle says nothing:
            # judge those intervals against the largest plausible rate instead
            dtg = np.diff(tg)
            holes = np.concatenate([[0], np.cumsum(dtg > 3.0 * np.median(dtg))])
            j0 = np.clip(np.searchsorted(tg, t[:-1], side="right") - 1, 0, tg.size - 1)
            j1 = np.clip(np.searchsorted(tg, t[1:], side="left"), 0, tg.size - 1)
            blind = holes[j1] > holes[j0]
            # the tracker's own noise may exceed the configured error (e.g. a boresight axis 5-10x the others):
            # at least k x the robust scatter of the residuals per axis (union bound: |e| <= k |sigma|)
            resid = (rot - expected)[~blind & np.all(np.isfinite(expected), axis=1)]
            if resid.shape[0] >= 20:
                sig = 1.4826 * np.median(np.abs(resid - np.median(resid, axis=0)), axis=0)
                tol = np.maximum(tol, p.k_quaternion * float(np.sqrt(np.sum(sig ** 2))))
            jump = np.where(blind, np.maximum(np.linalg.norm(rot, axis=1) - p.max_rate_rad_s * dt, 0.0), jump)
            tol = np.where(blind, p.k_quaternion * np.sqrt(2) * p.star_tracker_error_rad, tol)
            if intervals is not None:
                intervals.append((t, jump, tol))
        else:
            jump = np.maximum(np.linalg.norm(rot, axis=1) - p.max_rate_rad_s * dt, 0.0)
            tol = p.k_quaternion * np.sqrt(2) * p.star_tracker_error_rad * np.ones_like(dt)
        flagged = attribute_increments(np.where(np.isfinite(jump), jump > tol, False))
        stat = np.maximum(np.concatenate([[0.0], jump]), np.concatenate([jump, [0.0]]))
        col.add("quaternion_jump", rows, flagged, stat, float(np.nanmedian(tol)), "rad", "generic")


@dataclass(frozen=True)
class _StreamPart:
    """One non-GNSS stream to screen (a part for the mapper) with what its criteria need."""

    name: str
    cols: Columns
    spacecraft: Spacecraft
    gyro: Columns | None
    p: ScreeningParams
    track: GnssTrack | None
    env: Environment
    nav: Mapping[str, Any] | None


@dataclass(frozen=True)
class _StreamScreening:
    """What screening one stream gave; for GNSS also the track of its accepted states."""

    criteria: list[Criterion]
    n: int
    notes: list[str]
    findings: dict[str, Any]
    st_intervals: list[_Interval]
    track: GnssTrack | None = None


NEEDS_TRACK = frozenset({"magnetometer", "panel_currents", "gnss_visibility"})
"""Streams whose criteria need the spacecraft's position (the accepted GNSS states): screened after GNSS."""


@dataclass(frozen=True)
class _GnssPart:
    """The GNSS stream to screen (a part for the mapper)."""

    cols: Columns
    p: ScreeningParams
    reference_orbit: Columns | None
    reference_frame: str

    @property
    def name(self) -> str:
        return "gnss"


def _screen_part(part: _GnssPart | _StreamPart) -> _StreamScreening:
    """One part of :func:`screen`: the GNSS stream (its criteria and the track of its accepted states) or
    another stream."""
    if isinstance(part, _StreamPart):
        return _screen_stream(part)
    col = Collector("gnss", len(part.cols["time_tai_ns"]))
    notes: list[str] = []
    findings: dict[str, Any] = {}
    track = screen_gnss(col, part.cols, part.p, part.reference_orbit, part.reference_frame, notes, findings)
    return _StreamScreening(col.criteria(), col.n, notes, findings, [], track)


def _screen_stream(part: _StreamPart) -> _StreamScreening:
    """The criteria of one non-GNSS stream (the GNSS track already known)."""
    name, cols, p = part.name, part.cols, part.p
    notes: list[str] = []
    findings: dict[str, Any] = {}
    st_intervals: list[_Interval] = []
    n = len(cols["time_tai_ns"])
    for c in ("time_tai_ns", "sensor"):
        if c not in cols:
            raise ScreeningError(f"stream {name} lacks the column {c!r}")
    col = Collector(name, n)
    if name == "magnetometer":
        _screen_magnetometer(col, cols, p, part.track, part.env, notes, findings)
    elif name == "panel_currents":
        screen_panels(col, cols, part.spacecraft, p, part.track, part.env, notes, findings)
    elif name == "gnss_visibility":
        _screen_visibility(col, cols, p, part.track, part.nav, notes)
    elif name == "star_tracker":
        _screen_star_tracker(col, cols, part.spacecraft, part.gyro, p, findings, st_intervals)
    else:
        for _sensor, rows in sensor_groups(cols):
            generic_checks(col, cols, name, rows, p, findings=findings)
    return _StreamScreening(col.criteria(), n, notes, findings, st_intervals)


def screen(streams: Mapping[str, Columns], spacecraft: Spacecraft, params: ScreeningParams | None = None, *,
           env: Environment | None = None, reference_orbit: Columns | None = None, reference_frame: str = "ITRF",
           nav: Mapping[str, Any] | None = None, selected: Sequence[str] | None = None,
           mapper: Mapper = serial_map) -> ScreeningResult:
    """Apply every criterion that the available data allow to the selected streams.

    streams: {stream: columns} as in processing.tasks.TaskInputs (time_tai_ns, sensor, canonical
    columns); spacecraft: its configuration (solar panels; star-tracker and gyro mountings);
    reference_orbit: optional columns time_tai_ns, x, y, z, vx, vy, vz (m, m/s) in ``reference_frame``
    ("ITRF" or an inertial frame such as "GCRF"/"EME2000"); nav: rinex_nav columns for the
    visibility check. selected: streams to screen (default: all given). The streams are screened through
    ``mapper`` (processing.tasks.Mapper: e.g. across a cluster's workers; the result does not depend on it) in
    two passes: GNSS (when present) beside the streams whose criteria need no position (gyro, star tracker,
    ...), then the streams of :data:`NEEDS_TRACK`, which need the position that GNSS's accepted states give.
    """
    p = params or ScreeningParams()
    env = env or Environment()
    findings: dict[str, Any] = {}
    st_intervals: list[_Interval] = []
    chosen = list(streams) if selected is None else [s for s in selected if s in streams]
    notes: list[str] = []
    criteria: list[Criterion] = []
    n_rows: dict[str, int] = {}
    others = [name for name in chosen if name != "gnss"]
    # the streams whose criteria need no position are screened beside GNSS, the others once its track is known
    first: list[_GnssPart | _StreamPart] = [_StreamPart(name, streams[name], spacecraft, streams.get("gyro"), p,
                                                        None, env, nav)
                                            for name in others if name not in NEEDS_TRACK]
    if "gnss" in streams:
        first.insert(0, _GnssPart(streams["gnss"], p, reference_orbit, reference_frame))
    done: dict[str, _StreamScreening] = {}
    track: GnssTrack | None = None
    for part, out in zip(first, mapper(_screen_part, first), strict=True):
        if isinstance(part, _GnssPart):
            track = out.track
            notes += out.notes
            findings.update(out.findings)
            if "gnss" in chosen:
                criteria += out.criteria
                n_rows["gnss"] = out.n
        elif isinstance(part, _StreamPart):
            done[part.name] = out
    if "gnss" not in streams:
        notes.append("no GNSS stream: criteria needing the spacecraft position are not applied")
    second = [_StreamPart(name, streams[name], spacecraft, streams.get("gyro"), p, track, env, nav)
              for name in others if name in NEEDS_TRACK]
    done.update({part.name: out for part, out in zip(second, mapper(_screen_part, second), strict=True)})
    for name in others:  # merged in stream order, whichever pass screened them
        out = done[name]
        criteria += out.criteria
        n_rows[name] = out.n
        notes += out.notes
        st_intervals += out.st_intervals
        for key, value in out.findings.items():  # per stream: lists in stream order, dicts by stream
            if isinstance(value, list):
                findings.setdefault(key, []).extend(value)
            elif isinstance(value, dict):
                findings.setdefault(key, {}).update(value)
            else:
                findings[key] = value
    if p.transient_consistency and st_intervals and "gyro" in n_rows:
        criteria = _confirmed_transients(criteria, streams["gyro"], st_intervals, findings)
    return ScreeningResult(criteria=criteria, n_rows=n_rows, notes=notes, findings=findings)


def _confirmed_transients(criteria: list[Criterion], gyro: Columns,
                          intervals: list[_Interval],
                          findings: dict[str, Any]) -> list[Criterion]:
    """Gyro spikes that the star tracker sees too are real rate transients, not faults: the spike's excess
    rotation |w - median| (t_k+1 - t_k-1) / 2 would make every star-tracker interval over [t_k-1, t_k+1]
    fail quaternion_jump (it exceeds the tolerance there) if the gyro were wrong, and none fails. Those rows
    are taken out of ``spike`` and counted in findings["transients"]."""
    out = []
    for c in criteria:
        if c.stream != "gyro" or c.name != "spike" or not np.any(c.flagged):
            out.append(c)
            continue
        t = np.asarray(gyro["time_tai_ns"], dtype=np.int64)
        confirmed = np.zeros(c.flagged.size, dtype=bool)
        prev_row = np.arange(t.size)
        next_row = np.arange(t.size)
        for _sensor, rows in sensor_groups(gyro):  # time-order neighbours within each sensor
            prev_row[rows[1:]], next_row[rows[:-1]] = rows[:-1], rows[1:]
        for k in np.flatnonzero(c.flagged):
            lo, hi = t[prev_row[k]], t[next_row[k]]
            excess = c.statistic[k] * (hi - lo) / 2.0 / NS_PER_S
            for t_st, jump, tol in intervals:
                i0 = max(int(np.searchsorted(t_st, lo, side="right")) - 1, 0)
                i1 = min(int(np.searchsorted(t_st, hi, side="left")), t_st.size - 1)
                if i1 <= i0 or t_st[i0] > lo or t_st[i1] < hi:
                    continue
                j, tl = jump[i0:i1], tol[i0:i1]
                if np.all(np.isfinite(j)) and np.all(j <= tl) and excess > float(np.max(tl)):
                    confirmed[k] = True
                    break
        if np.any(confirmed):
            findings["transients"] = {"gyro_spikes_confirmed_by_star_tracker": int(confirmed.sum()),
                                      "first_tai_ns": [int(x) for x in t[confirmed][:10]]}
        out.append(replace(c, flagged=c.flagged & ~confirmed))
    return out
