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

Pure and vectorised; models are injectable (:class:`Environment`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.environment import igrf_field_E_nT, sun_position_I_m, sunlit_fraction
from processing.frames.earth_rotation_interp import gcrs_to_itrs_mat_interp
from processing.units import J2_EARTH, MU_EARTH_M3_S2, NS_PER_S, OMEGA_EARTH_RAD_S, R_EARTH_M

Columns = Mapping[str, NDArray[Any]]
VECTOR_COLUMNS = {
    "gnss": ("x", "y", "z", "vx", "vy", "vz"),
    "magnetometer": ("bx", "by", "bz"),
    "gyro": ("wx", "wy", "wz"),
    "gyro_increments": ("dax", "day", "daz"),
    "sun_sensor": ("sx", "sy", "sz"),
    "star_tracker": ("q0", "q1", "q2", "q3"),
    "magnetorquer": ("mx", "my", "mz"),
    "panel_currents": ("current_a",),
}
KEY_COLUMNS = {"panel_currents": ("panel",), "gnss_visibility": ("system", "prn")}
"""Columns besides (sensor, time) that identify a sample (processing.streams)."""



@dataclass(frozen=True)
class Environment:
    """Models used by the criteria (injectable for tests and other missions).

    field_E_nT(r_E (N, 3) m, tai_ns (N,)) -> (N, 3) nT ITRF; sun_position_I_m(tai_ns (N,)) -> (N, 3) m
    GCRS; sunlit_fraction(r_I (N, 3), r_sun_I (N, 3)) -> (N,) visible fraction of the solar disc.
    """

    field_E_nT: Callable[[NDArray[Any], NDArray[Any]], NDArray[Any]] = igrf_field_E_nT
    sun_position_I_m: Callable[[NDArray[Any]], NDArray[Any]] = sun_position_I_m
    sunlit_fraction: Callable[[NDArray[Any], NDArray[Any]], NDArray[Any]] = sunlit_fraction


@dataclass(frozen=True)
class ScreeningParams:
    """Thresholds. Each tolerance is k x (instrument error + model error) as in 002 eqs. 15-17.

    Defaults: a small-satellite GNSS receiver (10 m, 0.1 m/s, 1 sigma per axis), a magnetometer of
    100 nT noise and IGRF-14's ~150 nT omission/commission error in LEO (crustal and external fields
    in quiet conditions), panel currents read to 0.02 A with 0.03 A of model error (albedo,
    temperature); k = 3 to 6 so that Gaussian noise alone is flagged at a rate below 1e-4 (the
    paper only asks k > 1).
    """

    gnss_position_error_m: float = 10.0
    gnss_velocity_error_m_s: float = 0.1
    k_energy: float = 4.0
    energy_model: Literal["j2", "two_body"] = "j2"
    energy_model_error_m2_s2: float | None = None
    """Model error of h added to dh; None: 300 m^2/s^2 for "j2", 2.5e5 for "two_body" (J2_EARTH oscillation)."""
    k_plane: float = 5.0
    plane_window_s: float = 10.0
    """Half-width of the orbit-normal running median (at least 2 samples)."""
    k_kinematic: float = 6.0
    k_velocity: float = 6.0
    velocity_half_window: int = 8
    magnetometer_error_nT: float = 100.0
    field_model_error_nT: float = 150.0
    k_field: float = 3.0
    current_error_a: float = 0.02
    current_model_error_a: float = 0.03
    k_current: float = 3.0
    sun_norm: bool = True
    spike_half_window: int = 5
    k_spike: float = 6.0
    stuck_min_run: int = 10
    time_grid_tolerance: float = 0.25
    max_rate_rad_s: float = 0.1
    star_tracker_error_rad: float = 5e-5
    gyro_rate_error_rad_s: float = 1e-5
    k_quaternion: float = 6.0
    quaternion_norm_tolerance: float = 1e-3
    grazing_altitude_m: float = 50e3
    max_interpolation_gap_s: float = 30.0


@dataclass(frozen=True)
class Criterion:
    """One criterion applied to one stream: row masks aligned with the stream's rows.

    flagged: (n,) rejected by this criterion; applied: (n,) rows the criterion could judge;
    statistic: (n,) the tested quantity (NaN where not applied); threshold: its bound (same unit);
    unit: of statistic and threshold; source: the paper's equation or "generic".
    """

    stream: str
    name: str
    flagged: NDArray[np.bool_]
    applied: NDArray[np.bool_]
    statistic: NDArray[np.float64]
    threshold: float
    unit: str
    source: str


@dataclass(frozen=True)
class ScreeningResult:
    """All criteria applied; ``n_rows[stream]`` rows per screened stream; ``notes`` say what was skipped."""

    criteria: list[Criterion]
    n_rows: dict[str, int]
    notes: list[str] = field(default_factory=list)

    def rejected(self, stream: str) -> NDArray[np.bool_]:
        out = np.zeros(self.n_rows[stream], dtype=bool)
        for c in self.criteria:
            if c.stream == stream:
                out |= c.flagged
        return out

    def reasons(self, stream: str) -> NDArray[np.object_]:
        """(n,) ';'-joined names of the criteria that flagged each row ("" when accepted)."""
        parts = [np.where(c.flagged, c.name, "") for c in self.criteria if c.stream == stream]
        out = np.full(self.n_rows[stream], "", dtype=object)
        for p in parts:
            out = np.where(p == "", out, np.where(out == "", p, out + ";" + p))
        return out

    def summary(self) -> dict[str, dict[str, dict[str, Any]]]:
        """{stream: {criterion: {n_total, n_applied, n_rejected, threshold, unit, source}}} (JSON-able)."""
        out: dict[str, dict[str, dict[str, Any]]] = {}
        for c in self.criteria:
            out.setdefault(c.stream, {})[c.name] = {
                "n_total": int(c.flagged.size), "n_applied": int(c.applied.sum()), "n_rejected": int(c.flagged.sum()),
                "threshold": float(c.threshold), "unit": c.unit, "source": c.source}
        for stream, n in self.n_rows.items():
            rej = self.rejected(stream)
            out.setdefault(stream, {})["any"] = {"n_total": int(n), "n_applied": int(n),
                                                  "n_rejected": int(rej.sum()), "threshold": float("nan"),
                                                  "unit": "", "source": "union"}
        return out


from processing.screening.tools import (  # noqa: E402 - building blocks, re-exported
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

# ------------------------------------------------------------------------------------------------
# Panels and visibility helpers.


def pivot(times: NDArray[np.int64], keys: NDArray[Any]) -> tuple[NDArray[np.int64], NDArray[Any], NDArray[np.int64]]:
    """Long rows (time, key) -> epochs (T,), keys (K,), and index (T, K) of the row (-1 where none)."""
    ut, ti = np.unique(times, return_inverse=True)
    uk, ki = np.unique(keys, return_inverse=True)
    index = np.full((ut.size, uk.size), -1, dtype=np.int64)
    index[ti, ki] = np.arange(times.size)
    return ut, uk, index


def sun_from_currents(currents_a: ArrayLike, normals_B: ArrayLike, max_current_a: ArrayLike,
                      lit_threshold_a: float = 0.0, iterations: int = 5
                      ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Sun vector in the body frame from panel currents, I_i = I_max,i max(0, n_i . s) (002, eq. 17 model).

    currents_a: (T, P) (NaN: missing); normals_B: (P, 3); max_current_a: (P,). Gauss-Newton on the
    panels whose model is lit (n . s > 0), started from the least-squares solution of all panels
    (for opposite panel pairs that start is already along the sun). Returns (s_B (T, 3) not
    normalised: |s| = 1 for consistent currents; determined (T,): the normals of the panels that
    constrain s -- lit ones, and dark ones within lit_threshold of their terminator, n . s > -threshold
    / I_max, which pin the component along them to about zero -- span three dimensions).
    """
    cur = np.asarray(currents_a, dtype=np.float64)
    n = np.asarray(normals_B, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    imax = np.asarray(max_current_a, dtype=np.float64)
    y = cur / imax
    have = np.isfinite(y)
    y0 = np.where(have, y, 0.0)
    w = have.astype(float)
    a = np.einsum("tp,pi,pj->tij", w, n, n) + 1e-9 * np.eye(3)
    s = np.linalg.solve(a, np.einsum("tp,pi->ti", w * y0, n)[..., None])[..., 0]
    margin = lit_threshold_a / np.maximum(imax, 1e-12)
    for _ in range(iterations):
        wa = (have & (np.einsum("pi,ti->tp", n, s) > 0)).astype(float)
        a = np.einsum("tp,pi,pj->tij", wa, n, n) + 1e-9 * np.eye(3)
        s = np.linalg.solve(a, np.einsum("tp,pi->ti", wa * y0, n)[..., None])[..., 0]
    constraining = have & (np.einsum("pi,ti->tp", n, s) > -margin)
    span = np.einsum("tp,pi,pj->tij", constraining.astype(float), n, n)
    determined = np.linalg.eigvalsh(span)[:, 0] > 1e-3
    return s, determined


# ------------------------------------------------------------------------------------------------
# Screening of each stream.


def _sensor_groups(cols: Columns) -> list[tuple[str, NDArray[np.int64]]]:
    sensors = np.asarray(cols["sensor"], dtype=object).astype(str)
    t = np.asarray(cols["time_tai_ns"], dtype=np.int64)
    out = []
    for s in sorted(set(sensors.tolist())):
        idx = np.flatnonzero(sensors == s)
        out.append((s, idx[np.argsort(t[idx], kind="stable")]))
    return out


class _Collector:
    """Accumulates per-row criterion masks of a stream across its sensor groups."""

    def __init__(self, stream: str, n: int) -> None:
        self.stream = stream
        self.n = n
        self.items: dict[str, dict[str, Any]] = {}

    def add(self, name: str, rows: NDArray[np.int64], flagged: ArrayLike, statistic: ArrayLike, threshold: float,
            unit: str, source: str, applied: ArrayLike | None = None) -> None:
        it = self.items.setdefault(name, {
            "flagged": np.zeros(self.n, bool), "applied": np.zeros(self.n, bool), "statistic": np.full(self.n, np.nan),
            "thresholds": [], "unit": unit, "source": source})
        f = np.asarray(flagged, dtype=bool)
        app = np.ones(rows.size, bool) if applied is None else np.asarray(applied, dtype=bool)
        stat = np.asarray(statistic, dtype=np.float64)
        it["flagged"][rows] |= f & app
        it["applied"][rows] |= app
        it["statistic"][rows] = np.where(app, stat, np.nan)
        it["thresholds"].append(float(threshold))

    def criteria(self) -> list[Criterion]:
        out = []
        for name, it in self.items.items():
            th = [x for x in it["thresholds"] if np.isfinite(x)]
            out.append(Criterion(self.stream, name, it["flagged"], it["applied"], it["statistic"],
                                 float(np.max(th)) if th else float("nan"), it["unit"], it["source"]))
        return out


def _generic(col: _Collector, cols: Columns, stream: str, rows: NDArray[np.int64], p: ScreeningParams,
             spike: bool = True, stuck_ignore: NDArray[np.bool_] | None = None) -> None:
    t = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
    flagged, dev, period = time_grid(t, p.time_grid_tolerance)
    col.add("time_grid", rows, flagged, dev, p.time_grid_tolerance, "fraction of the sampling period", "generic")
    names = VECTOR_COLUMNS.get(stream)
    if names is None:
        return
    values = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in names], axis=1)
    col.add("stuck", rows, stuck(values, p.stuck_min_run, stuck_ignore), np.full(rows.size, np.nan),
            float(p.stuck_min_run), "samples", "generic")
    if spike and rows.size > 2 * p.spike_half_window:
        dist, th, f = hampel(values, p.spike_half_window, p.k_spike)
        col.add("spike", rows, f, dist, th, _UNITS.get(stream, ""), "generic")


_UNITS = {"magnetometer": "nT", "gyro": "rad/s", "gyro_increments": "rad", "sun_sensor": "", "magnetorquer": "A m^2",
          "gnss": "m, m/s", "panel_currents": "A", "star_tracker": ""}


@dataclass(frozen=True)
class GnssTrack:
    """Accepted GNSS states used as the position model of the other criteria (ITRF)."""

    time_tai_ns: NDArray[np.int64]
    r_E: NDArray[np.float64]
    v_E: NDArray[np.float64]

    def at(self, t_ns: ArrayLike, max_gap_s: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return hermite_state(self.time_tai_ns, self.r_E, self.v_E, t_ns, max_gap_s)


def _reference_h(reference: Columns, frame: str, t_ns: NDArray[np.int64], model: str) -> NDArray[np.float64]:
    from scipy.interpolate import CubicSpline

    tr = np.asarray(reference["time_tai_ns"], dtype=np.int64)
    r = np.stack([np.asarray(reference[c], dtype=np.float64) for c in ("x", "y", "z")], axis=1)
    v = np.stack([np.asarray(reference[c], dtype=np.float64) for c in ("vx", "vy", "vz")], axis=1)
    order = np.argsort(tr)
    tr, r, v = tr[order], r[order], v[order]
    if frame.upper() not in ("ITRF", "ITRS", "E"):  # inertial reference: to ITRF for the J2_EARTH latitude
        m = gcrs_to_itrs_mat_interp(tr)
        r_e = np.einsum("nij,nj->ni", m, r)
        v_e = np.einsum("nij,nj->ni", m, v) - np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], r_e)
        r, v = r_e, v_e
    h = energy_h(r, v, model)
    out = np.full(t_ns.size, np.nan)
    if tr.size < 4:
        return out
    x = (tr - tr[0]) / NS_PER_S
    spline = CubicSpline(x, h)
    xq = (t_ns - tr[0]) / NS_PER_S
    inside = (xq >= x[0]) & (xq <= x[-1])
    out[inside] = spline(xq[inside])
    return out


def _screen_gnss(col: _Collector, cols: Columns, p: ScreeningParams, reference: Columns | None,
                 reference_frame: str, notes: list[str]) -> GnssTrack | None:
    track = None
    for _sensor, rows in _sensor_groups(cols):
        t = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        r = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in ("x", "y", "z")], axis=1)
        v = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in ("vx", "vy", "vz")], axis=1)
        dr, dv = p.gnss_position_error_m, p.gnss_velocity_error_m_s
        bad = np.zeros(rows.size, bool)
        # Kinematic consistency of positions (increments vs trapezoid of velocities).
        dt = np.diff(t) / NS_PER_S
        d = np.linalg.norm(r[1:] - r[:-1] - 0.5 * (v[1:] + v[:-1]) * dt[:, None], axis=1)
        jerk = jerk_bound_m_s3(r, v)
        # noise of the increment, plus the trapezoid's truncation error dt^3 / 12 |r'''| (1.7 mm at 1 s)
        tol_inc = (p.k_kinematic * np.sqrt(2 * dr**2 + 0.5 * (dt * dv) ** 2)
                   + dt**3 / 12.0 * np.maximum(jerk[1:], jerk[:-1]))
        kin = attribute_increments(d > tol_inc)
        stat = np.maximum(np.concatenate([[0.0], d]), np.concatenate([d, [0.0]]))
        col.add("kinematic", rows, kin, stat, float(p.k_kinematic * np.sqrt(2 * dr**2 + 0.5 * dv**2)), "m", "generic")
        bad |= kin
        # Energy integral (eq. 15).
        h = energy_h(r, v, p.energy_model)
        model_err = p.energy_model_error_m2_s2
        if model_err is None:
            model_err = 300.0 if p.energy_model == "j2" else 2.5e5
        tol = p.k_energy * (energy_tolerance(r, v, dr, dv) + model_err)
        h_ref = None
        if reference is not None:
            h_ref = _reference_h(reference, reference_frame, t, p.energy_model)
            if not np.any(np.isfinite(h_ref)):
                notes.append("the reference orbit does not cover the GNSS samples; energy compared with a robust fit")
                h_ref = None
        if h_ref is None:
            h_ref = robust_polyfit((t - t[0]) / NS_PER_S, h, 1, exclude=bad)
        dev = np.abs(h - h_ref)
        applied = np.isfinite(dev)
        col.add("energy", rows, dev > tol, dev, float(np.nanmedian(tol)), "m^2/s^2", "002 eq. 15", applied)
        bad |= applied & (dev > tol)
        # Orbit plane.
        vi = inertial_velocity_E(r, v)
        nrm = np.cross(r, vi)
        nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        # Undo the Earth's rotation (about z, from the first sample) so that the normal is nearly fixed
        # and a one-sided window (next to rejected samples) does not bias the median.
        theta = OMEGA_EARTH_RAD_S * (t - t[0]) / NS_PER_S
        ct, st_ = np.cos(theta), np.sin(theta)
        nrm = np.stack([ct * nrm[:, 0] - st_ * nrm[:, 1], st_ * nrm[:, 0] + ct * nrm[:, 1], nrm[:, 2]], axis=1)
        period_s = float(np.median(dt)) if dt.size else 1.0
        hw = max(2, int(round(p.plane_window_s / max(period_s, 1e-9))))
        med = rolling_median(nrm, hw, exclude=bad)
        med = med / np.linalg.norm(med, axis=1, keepdims=True)
        ang = np.arccos(np.clip(np.sum(nrm * med, axis=1), -1.0, 1.0))
        rn = np.linalg.norm(r, axis=1)
        # noise, plus the J2_EARTH wobble of the normal (rate < 3 J2_EARTH (R/r)^2 n) over half the window, which a
        # one-sided window (next to rejected samples or at the ends) turns into a bias
        wobble = 3.0 * J2_EARTH * (R_EARTH_M / rn) ** 2 * np.sqrt(MU_EARTH_M3_S2 / rn**3) * 0.5 * hw * period_s
        tol_plane = p.k_plane * (dv / np.linalg.norm(vi, axis=1) + dr / rn) + wobble
        applied = np.isfinite(ang)
        col.add("orbit_plane", rows, ang > tol_plane, ang, float(np.nanmedian(tol_plane)), "rad", "generic", applied)
        bad |= applied & (ang > tol_plane)
        # Velocity against the local slope of the positions.
        v_fit, gain, cubic_gain = local_velocity_fit(t, r, p.velocity_half_window, exclude=bad)
        dvv = np.linalg.norm(v - v_fit, axis=1)
        # noise of v and of the slope, plus the slope's bias from the orbit's jerk (0.07 m/s at 1 s)
        tol_v = p.k_velocity * np.sqrt((gain * dr) ** 2 + dv**2) + cubic_gain * jerk / 6.0
        applied = np.isfinite(dvv)
        col.add("velocity", rows, dvv > tol_v, dvv, float(np.nanmedian(tol_v)), "m/s", "generic", applied)
        bad |= applied & (dvv > tol_v)
        flagged, dev_t, _ = time_grid(t, p.time_grid_tolerance)
        col.add("time_grid", rows, flagged, dev_t, p.time_grid_tolerance, "fraction of the sampling period", "generic")
        col.add("stuck", rows, stuck(np.concatenate([r, v], axis=1), p.stuck_min_run), np.full(rows.size, np.nan),
                float(p.stuck_min_run), "samples", "generic")
        bad |= flagged
        if track is None and np.sum(~bad) >= 2:
            track = GnssTrack(t[~bad], r[~bad], v[~bad])
    return track


def _screen_magnetometer(col: _Collector, cols: Columns, p: ScreeningParams, track: GnssTrack | None,
                         env: Environment, notes: list[str]) -> None:
    for _sensor, rows in _sensor_groups(cols):
        _generic(col, cols, "magnetometer", rows, p)
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


def _panel_config(config: Mapping[str, Any]) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    panels = config.get("solar_panels") or []
    if not panels:
        return None
    normals = np.array([p["normal_B"] for p in panels], dtype=np.float64)
    imax = np.array([p["max_current_a"] for p in panels], dtype=np.float64)
    return normals, imax


def _screen_panels(col: _Collector, cols: Columns, config: Mapping[str, Any], p: ScreeningParams,
                   track: GnssTrack | None, env: Environment, notes: list[str]) -> None:
    panel_cfg = _panel_config(config)
    d_i = p.current_error_a + p.current_model_error_a
    tol = p.k_current * d_i
    for _sensor, rows in _sensor_groups(cols):
        t_all = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        panel = np.asarray(cols["panel"], dtype=np.int64)[rows]
        cur = np.asarray(cols["current_a"], dtype=np.float64)[rows]
        for k in np.unique(panel):
            sub = rows[panel == k]
            _generic(col, cols, "panel_currents", sub, p,
                     stuck_ignore=np.abs(np.asarray(cols["current_a"], dtype=float)[sub]) <= tol)
        if panel_cfg is None:
            continue
        normals, imax = panel_cfg
        known = (panel >= 0) & (panel < imax.size)
        if not np.all(known):
            notes.append(f"{int(np.sum(~known))} panel_currents rows name panels not in the configuration")
        im = np.where(known, imax[np.clip(panel, 0, imax.size - 1)], np.nan)
        stat = np.where(cur < 0, -cur, np.maximum(cur - im, 0.0))
        col.add("panel_range", rows, (cur < -tol) | (cur > im + tol), stat, tol, "A", "002 eq. 17", known)
        if track is None:
            continue
        epochs, keys, index = pivot(t_all, panel)
        r_E, _ = track.at(epochs, p.max_interpolation_gap_s)
        ok = np.isfinite(r_E).all(axis=1)
        nu = np.full(epochs.size, np.nan)
        if np.any(ok):
            r_I = np.einsum("nji,nj->ni", gcrs_to_itrs_mat_interp(epochs[ok]), r_E[ok])
            nu[ok] = env.sunlit_fraction(r_I, env.sun_position_I_m(epochs[ok]))
        row_nu = np.full(rows.size, np.nan)
        ti = np.searchsorted(epochs, t_all)
        row_nu = nu[ti]
        applied = np.isfinite(row_nu) & known & (row_nu < 1.0)
        excess = cur - row_nu * np.nan_to_num(im)
        col.add("panel_eclipse", rows, applied & (excess > tol), np.where(applied, excess, np.nan), tol, "A",
                "002 eq. 17", applied)
        if not p.sun_norm:
            continue
        # Attitude-free form of eq. 17: in full sunlight the currents must give a unit sun vector.
        valid_keys = (keys >= 0) & (keys < imax.size)
        kk = keys[valid_keys]
        mat = np.full((epochs.size, kk.size), np.nan)
        idx = index[:, valid_keys]
        mat[idx >= 0] = cur[idx[idx >= 0]]
        pre = col.items.get("spike", {}).get("flagged")
        if pre is not None:
            # samples already rejected as spikes do not vote
            rej = np.zeros(mat.shape, bool)
            rej[idx >= 0] = pre[rows[idx[idx >= 0]]]
            mat = np.where(rej, np.nan, mat)
        s, determined = sun_from_currents(mat, normals[kk], imax[kk], lit_threshold_a=tol)
        complete = np.isfinite(mat).all(axis=1) & (kk.size == imax.size)  # a missing panel biases |s|
        sunlit = (nu >= 1.0) & complete
        lit = np.isfinite(mat) & (mat > tol)
        n_lit = lit.sum(axis=1)
        norm_dev = np.abs(np.linalg.norm(s, axis=1) - 1.0)
        tol_norm = p.k_current * d_i * np.sqrt(np.maximum(n_lit, 1)) / float(np.min(imax[kk]))
        bad_epoch = sunlit & determined & (norm_dev > tol_norm)
        applied_epoch = sunlit & determined
        row_flag = np.zeros(rows.size, bool)
        row_applied = np.zeros(rows.size, bool)
        row_stat = np.full(rows.size, np.nan)
        sel = idx >= 0
        ep = np.nonzero(sel)[0]
        rr = idx[sel]
        row_flag[rr] = bad_epoch[ep] & lit[sel]
        row_applied[rr] = applied_epoch[ep]
        row_stat[rr] = norm_dev[ep]
        th_norm = float(np.median(tol_norm[applied_epoch])) if np.any(applied_epoch) else float("nan")
        col.add("panel_sun_norm", rows, row_flag, row_stat, th_norm, "", "002 eq. 17", row_applied)
    if track is None:
        notes.append("no accepted GNSS samples: panel_eclipse and panel_sun_norm (eq. 17) not applied")


def _screen_visibility(col: _Collector, cols: Columns, p: ScreeningParams, track: GnssTrack | None,
                       nav: Mapping[str, Any] | None, notes: list[str]) -> None:
    from processing.orbits.gnss_ephemeris import satellite_positions_E
    from processing.vector_attitude.antenna_axis import dcm_EO_002, earth_occulted, line_of_sight_O

    for _sensor, rows in _sensor_groups(cols):
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


def _screen_star_tracker(col: _Collector, cols: Columns, config: Mapping[str, Any], gyro: Columns | None,
                         p: ScreeningParams) -> None:
    for sensor, rows in _sensor_groups(cols):
        q = np.stack([np.asarray(cols[c], dtype=np.float64)[rows] for c in ("q0", "q1", "q2", "q3")], axis=1)
        t = np.asarray(cols["time_tai_ns"], dtype=np.int64)[rows]
        norm_dev = np.abs(np.linalg.norm(q, axis=1) - 1.0)
        col.add("quaternion_norm", rows, norm_dev > p.quaternion_norm_tolerance, norm_dev, p.quaternion_norm_tolerance,
                "", "generic")
        _generic(col, cols, "star_tracker", rows, p, spike=False)
        if rows.size < 2:
            continue
        qn = q / np.linalg.norm(q, axis=1, keepdims=True)
        dq = rotations.quat_multiply(rotations.quat_conjugate(qn[:-1]), qn[1:])  # in sensor frame S
        rot = rotations.quat_to_rotvec(dq)
        dt = np.diff(t) / NS_PER_S
        if gyro is not None and len(gyro.get("time_tai_ns", [])) >= 2:
            q_BS = np.asarray(((config.get("star_trackers") or {}).get(sensor) or {}).get("q_BS", [1, 0, 0, 0]), float)
            q_BG = np.asarray((config.get("gyro") or {}).get("q_BG", [1, 0, 0, 0]), float)
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
        else:
            jump = np.maximum(np.linalg.norm(rot, axis=1) - p.max_rate_rad_s * dt, 0.0)
            tol = p.k_quaternion * np.sqrt(2) * p.star_tracker_error_rad * np.ones_like(dt)
        flagged = attribute_increments(np.where(np.isfinite(jump), jump > tol, False))
        stat = np.maximum(np.concatenate([[0.0], jump]), np.concatenate([jump, [0.0]]))
        col.add("quaternion_jump", rows, flagged, stat, float(np.nanmedian(tol)), "rad", "generic")


def screen(streams: Mapping[str, Columns], config: Mapping[str, Any], params: ScreeningParams | None = None, *,
           env: Environment | None = None, reference_orbit: Columns | None = None, reference_frame: str = "ITRF",
           nav: Mapping[str, Any] | None = None, selected: Sequence[str] | None = None) -> ScreeningResult:
    """Apply every criterion that the available data allow to the selected streams.

    streams: {stream: columns} as in processing.tasks.TaskInputs (time_tai_ns, sensor, canonical
    columns); config: spacecraft configuration (solar_panels, star_trackers, gyro, ...);
    reference_orbit: optional columns time_tai_ns, x, y, z, vx, vy, vz (m, m/s) in ``reference_frame``
    ("ITRF" or an inertial frame such as "GCRF"/"EME2000"); nav: rinex_nav columns for the
    visibility check. selected: streams to screen (default: all given). GNSS is always screened first
    when present, because its accepted samples give the position the other models need.
    """
    p = params or ScreeningParams()
    env = env or Environment()
    chosen = list(streams) if selected is None else [s for s in selected if s in streams]
    notes: list[str] = []
    criteria: list[Criterion] = []
    n_rows: dict[str, int] = {}
    track: GnssTrack | None = None
    if "gnss" in streams:
        gcol = _Collector("gnss", len(streams["gnss"]["time_tai_ns"]))
        track = _screen_gnss(gcol, streams["gnss"], p, reference_orbit, reference_frame, notes)
        if "gnss" in chosen:
            criteria += gcol.criteria()
            n_rows["gnss"] = gcol.n
    else:
        notes.append("no GNSS stream: criteria needing the spacecraft position are not applied")
    for name in chosen:
        if name == "gnss":
            continue
        cols = streams[name]
        n = len(cols["time_tai_ns"])
        for c in ("time_tai_ns", "sensor"):
            if c not in cols:
                raise ScreeningError(f"stream {name} lacks the column {c!r}")
        col = _Collector(name, n)
        if name == "magnetometer":
            _screen_magnetometer(col, cols, p, track, env, notes)
        elif name == "panel_currents":
            _screen_panels(col, cols, config, p, track, env, notes)
        elif name == "gnss_visibility":
            _screen_visibility(col, cols, p, track, nav, notes)
        elif name == "star_tracker":
            _screen_star_tracker(col, cols, config, streams.get("gyro"), p)
        else:
            for _sensor, rows in _sensor_groups(cols):
                _generic(col, cols, name, rows, p)
        criteria += col.criteria()
        n_rows[name] = n
    return ScreeningResult(criteria=criteria, n_rows=n_rows, notes=notes)


