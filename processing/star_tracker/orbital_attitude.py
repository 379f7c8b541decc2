"""Attitude relative to the orbital frame from star-tracker quaternions and GNSS states (003 §1.6).

003 §1.6 computes the orbital attitude of Meteor-M in three steps: (1) body -> inertial from the
smoothed star-tracker quaternion q_sm(t) (§1.3) and the mounting; (2) inertial -> Greenwich by the
sidereal rotation S(t) = S0 + w_e t about X3; (3) Greenwich -> orbital from the GNSS r, v (smoothed,
errors < 1 m, < 1 mm/s). The orbital frame has axis 3 along the radius vector, axis 2 along the
orbital angular momentum and axis 1 completing it; the angles are pitch alpha about axis 2, yaw
beta about the new axis 3 and roll gamma about the resulting axis 1 (processing.attitude.rotations
.quat_from_pitch_yaw_roll). Paper: |alpha|, |gamma| < 0.4 deg, beta oscillating < 0.3 deg about
1.0-1.4 deg; fig. 12 plots segments against the time since the preceding ascending node.

Here, with the modern equivalents:

1. q_XS (sensor -> frame X, X = GCRF, EME2000, MOD, TOD or TEME as the star tracker reports) is
   taken to the GCRS, q_GS = q_GX o q_XS (processing.frames.earth_orientation; the paper's X1X2X3 is MOD). Assuming
   GCRF quaternions to be MOD -- 003's simplification -- turns them by the precession since J2000
   (0.33 deg in 2023), which is what the ``inertial_frame`` parameter prevents.
2. The GNSS ITRF states are smoothed (processing.orbits.gnss_orbit) and taken to the GCRS with
   IAU 2006/2000A and the given Earth orientation (the full celestial-terrestrial rotation instead of
   S(t) about X3: the difference, precession-nutation and polar motion, is the size of step 1's).
3. The orbital frame O from the inertial r, v (``orbital_003`` or ``lvlh_004``,
   processing.frames.orbital); q_OS = q_GO^-1 o q_GS.
4. Smoothing (003 §1.3) of the star-tracker attitude. The paper smooths q_IS itself; over 20 min
   in orbital orientation that attitude turns by ~70 deg and its sine series needs many harmonics
   (the Rodrigues parameters' coefficients decay as m^-3), which pass on more of the noise. The
   orbital rotation is known from GNSS, so by default (``smoothing_frame="orbital"``) the same
   §1.3 smoother -- mean quaternion, Rodrigues parameters z of q_c^-1 o q_n, sine series plus trend
   per component, harmonic count by GCV -- is applied to q_OS, which moves by a fraction of a degree:
   the smoothed q_OS(t) is the §1.3 q_sm with the orbital motion as the reference motion.
   ``smoothing_frame="inertial"`` smooths q_GS as 003 does (for comparison).
5. q_OB = q_OS o q_BS^-1, angles from q_OB; the body attitude q_GB = q_GO o q_OB (for the AEM).

Inputs: times int64 tai_ns; quaternions scalar first, unit; states ITRF m, m/s. Angles rad.

The trend-plus-sines fit of step 4 is in processing.star_tracker.trend_sines; the JSON-able summary and
segment table of a result (summary_of, segment_table) in processing.star_tracker.orbital_attitude_summary.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.frames.earth_orientation import EarthOrientation, canonical_inertial_frame, inertial_to_gcrs_mat
from processing.frames.orbital import q_IO_003, q_IO_lvlh_004
from processing.orbits.gnss_checks import GnssFitCheck, check_gnss_fit
from processing.orbits.gnss_orbit import (
    EopSource,
    GnssFit,
    ascending_nodes,
    fit_gnss,
    gnss_to_gcrs,
    time_since_ascending_node_s,
)
from processing.star_tracker.smoothing import (
    mean_quaternion,
    residual_mrps,
    sensor_axis_residuals,
    split_segments,
)
from processing.star_tracker.trend_sines import fit_trend_sines
from processing.units import NS_PER_S

ORBITAL_FRAMES = ("orbital_003", "lvlh_004")
MIN_SMOOTHING_SAMPLES = 12
SEGMENT_MAX_S = 1200.0
"""003 §1.3: segments of at most 20 min."""

SmoothingFrame = Literal["orbital", "inertial"]
EulerSequence = Literal["231", "321"]
EULER_SEQUENCES: dict[str, str] = {
    "231": "2-3-1: pitch about orbital axis 2, then yaw about the new axis 3, then roll about the new axis 1 "
           "(003 §1.6)",
    "321": "3-2-1: yaw about orbital axis 3, then pitch about the new axis 2, then roll about the new axis 1 "
           "(the common LVLH yaw-pitch-roll)",
}
"""The Euler sequences offered for the reported angles (intrinsic, from the orbital frame O to the body B)."""
MANOEUVRE_K = 8.0
"""A manoeuvre: the smoothed rate relative to the orbital frame beyond median + k x robust scale."""
MANOEUVRE_HALF_WINDOW = 5


class OrbitalAttitudeError(ValueError):
    """Inputs that do not allow the 003 §1.6 computation; the message says what and why."""


@dataclass(frozen=True)
class SmoothingSegment:
    """One smoothed segment: sample index range [start, stop), harmonics M of z1, z2, z3 (-1: too few
    samples, not smoothed), residual rms about the sensor axes x1 x2 x3 [rad] (the smoothing
    residuals: star-tracker noise + motion the series does not follow, e.g. 003's 0.4 Hz line)."""

    start: int
    stop: int
    harmonics: tuple[int, int, int]
    residual_rms_rad: NDArray

    @property
    def smoothed(self) -> bool:
        return min(self.harmonics) >= 0


@dataclass(frozen=True)
class OrbitalAttitude:
    """Result of :func:`orbital_attitude` (all per-sample arrays over the N star-tracker samples used).

    time_tai_ns (N,); q_GB (N, 4) body attitude in the GCRS (smoothed when smoothing is on); q_OB
    (N, 4); pitch/yaw/roll_rad (N,) from q_OB (003 §1.6) and *_raw_rad without smoothing;
    time_since_node_s (N,) ("virtual orbit"); ascending_nodes_tai_ns (K,) found in the GNSS arcs;
    r_I, v_I (N, 3) GCRS state at the samples; dropped_tai_ns: star-tracker times outside the GNSS
    coverage (not used); gnss: the orbit fit; segments: smoothing segments (empty if off).
    """

    time_tai_ns: NDArray
    q_GB: NDArray
    q_OB: NDArray
    pitch_rad: NDArray
    yaw_rad: NDArray
    roll_rad: NDArray
    pitch_raw_rad: NDArray
    yaw_raw_rad: NDArray
    roll_raw_rad: NDArray
    time_since_node_s: NDArray
    ascending_nodes_tai_ns: NDArray
    r_I: NDArray
    v_I: NDArray
    dropped_tai_ns: NDArray
    gnss: GnssFit
    inertial_frame: str
    orbital_frame: str
    smoothing: bool
    smoothing_frame: str
    segments: tuple[SmoothingSegment, ...] = field(default=())
    euler_sequence: str = "231"
    q_OB_raw: NDArray | None = None
    manoeuvres_tai_ns: tuple[tuple[int, int], ...] = ()
    gnss_check: GnssFitCheck | None = None
    orbit_frame_sigma_rad: NDArray | None = None
    """(3,) error of the orbital frame from the GNSS fit, about the pitch, yaw and roll axes."""
    attitude_sigma_rad: NDArray | None = None
    """(3,) star-tracker part of the angle error (smoothed: the fit's; raw: the noise), pitch, yaw, roll."""
    gnss_recheck: GnssFitCheck | None = None
    gnss_dropped_late: int = 0

    def angle_statistics_deg(self, raw: bool = False, sequence: str | None = None) -> dict[str, dict[str, float]]:
        """{pitch_deg, yaw_deg, roll_deg: {mean, std, min, max}} in degrees (the job summary);
        ``raw``: of the unsmoothed angles; ``sequence``: in another Euler sequence than the result's.
        See :func:`angle_stats_deg`."""
        if sequence is not None and sequence != self.euler_sequence:
            q = self.q_OB_raw if raw and self.q_OB_raw is not None else self.q_OB
            series = euler_angles(q, sequence)
        else:
            series = ((self.pitch_raw_rad, self.yaw_raw_rad, self.roll_raw_rad) if raw
                      else (self.pitch_rad, self.yaw_rad, self.roll_rad))
        return {name: angle_stats_deg(a) for name, a in zip(("pitch_deg", "yaw_deg", "roll_deg"), series, strict=True)}


def euler_angles(q_OB: ArrayLike, sequence: str) -> tuple[NDArray, NDArray, NDArray]:
    """(pitch, yaw, roll) [rad] of q_OB (..., 4) in an intrinsic Euler sequence (EULER_SEQUENCES).

    "231": processing.attitude.rotations.pitch_yaw_roll_from_quat (003 §1.6: q_OB = q_y(pitch) o q_z(yaw) o
    q_x(roll)); "321": q_OB = q_z(yaw) o q_y(pitch) o q_x(roll) (scipy's intrinsic "ZYX"), pitch in
    [-90, 90] deg, singular at pitch +-90 deg where 2-3-1 is singular at yaw +-90 deg (a yaw manoeuvre).
    """
    if sequence == "231":
        return rotations.pitch_yaw_roll_from_quat(q_OB)
    if sequence == "321":
        from scipy.spatial.transform import Rotation

        q = np.asarray(q_OB, dtype=np.float64)
        yaw, pitch, roll = np.moveaxis(
            Rotation.from_quat(q.reshape(-1, 4), scalar_first=True).as_euler("ZYX").reshape(q.shape[:-1] + (3,)),
            -1, 0)
        return pitch, yaw, roll
    raise OrbitalAttitudeError(f"euler_sequence must be one of {', '.join(EULER_SEQUENCES)}, got {sequence!r}")


def detect_manoeuvres(time_tai_ns: NDArray, q: NDArray, *, k: float = MANOEUVRE_K,
                      half_window: int = MANOEUVRE_HALF_WINDOW, max_gap_s: float = 60.0) -> list[tuple[int, int]]:
    """Manoeuvres in an attitude series q (N, 4) relative to a reference motion (q_OS: the orbital frame).

    The rate of each interval, rotvec(q_k^-1 q_k+1) / dt, is averaged over +-half_window intervals (the
    star-tracker noise averages down; intervals across gaps > max_gap_s are left out); its norm beyond
    median + k x 1.4826 MAD (both from the data: the attitude's normal motion and noise) starts a
    manoeuvre, which extends on both sides while the norm stays above median + 2 x the scale (hysteresis:
    the slow start and end of the turn belong to it). Returns [start, stop) sample index ranges.
    """
    n = time_tai_ns.size
    if n < 4 * half_window + 4:
        return []
    dq = rotations.quat_multiply(rotations.quat_conjugate(q[:-1]), q[1:])
    dt = np.diff(time_tai_ns).astype(np.float64) / NS_PER_S
    ok = dt <= max_gap_s
    rate = np.where(ok[:, None], rotations.quat_to_rotvec(dq) / dt[:, None], 0.0)
    w = 2 * half_window + 1
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(rate, axis=0)])
    cn = np.concatenate([[0], np.cumsum(ok)])
    lo = np.clip(np.arange(n - 1) - half_window, 0, n - 1)
    hi = np.clip(np.arange(n - 1) + half_window + 1, 0, n - 1)
    cnt = np.maximum(cn[hi] - cn[lo], 1)
    mean = (c[hi] - c[lo]) / cnt[:, None]
    norm = np.linalg.norm(mean, axis=1)
    med = float(np.median(norm[ok]))
    scale = 1.4826 * float(np.median(np.abs(norm[ok] - med)))
    high = ok & (norm > med + k * scale) & (cnt >= w // 2)
    if not np.any(high):
        return []
    low = norm > med + 2.0 * scale
    runs = np.concatenate([[0], np.cumsum(np.diff(low.astype(np.int8)) != 0)])  # runs of equal 'low'
    keep = np.unique(runs[high])
    out: list[tuple[int, int]] = []
    for r in keep:
        idx = np.flatnonzero(runs == r)
        a, b = int(idx[0]), int(idx[-1]) + 2  # intervals a..b-2 -> samples a..b-1
        if out and a <= out[-1][1] + w:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def angle_stats_deg(a_rad: ArrayLike) -> dict[str, float]:
    """{mean, std, min, max} [deg] of an angle series, taken on the continuous (unwrapped) series so that
    an attitude near +-180 deg (e.g. a satellite flying backwards) does not average to 0; the mean is
    then wrapped into (-180, 180], min and max are those of the continuous series."""
    d = np.degrees(np.unwrap(np.asarray(a_rad, dtype=np.float64)))
    mean = float(np.mean(d))
    wrapped = float((mean + 180.0) % 360.0 - 180.0)
    shift = wrapped - mean
    return {"mean": wrapped, "std": float(np.std(d, ddof=1)) if d.size > 1 else 0.0,
            "min": float(np.min(d) + shift), "max": float(np.max(d) + shift)}


def _q_GO(r_I: NDArray, v_I: NDArray, orbital_frame: str) -> NDArray:
    if orbital_frame == "orbital_003":
        return q_IO_003(r_I, v_I)
    if orbital_frame == "lvlh_004":
        return q_IO_lvlh_004(r_I, v_I)
    raise OrbitalAttitudeError(f"orbital_frame must be one of {', '.join(ORBITAL_FRAMES)}, got {orbital_frame!r}")


def smooth_attitude(
    time_tai_ns: NDArray, q: NDArray, *, harmonics: int | None = None, trend_degree: int = 3,
    segment_max_s: float = SEGMENT_MAX_S, max_gap_s: float = 60.0, breaks: tuple[int, ...] = (),
) -> tuple[NDArray, tuple[SmoothingSegment, ...]]:
    """003 §1.3 smoothing of an attitude series q (N, 4) (any frame pair); returns q_sm at the samples.

    Per segment (split at gaps > max_gap_s, pieces <= segment_max_s): q_c = mean quaternion, z =
    Rodrigues parameters of q_c^-1 o q_n, each z_i fitted on its own (003 §1.3; each component has
    its own noise, the boresight one 5-10x the others, 003 §2.1) by a polynomial trend of degree
    ``trend_degree`` plus the sine series (:func:`fit_trend_sines`; trend_degree=1 is 003's exact
    form), M_i by generalised cross-validation -- it minimises the expected error of the fit at the
    samples, which is what the angles need -- unless ``harmonics`` is given; q_sm = q_c o s(z_fit).
    Segments with fewer than MIN_SMOOTHING_SAMPLES samples are returned unsmoothed (harmonics -1).
    ``breaks``: sample indices where a segment must also start (manoeuvre boundaries).
    """
    out = q.copy()
    segs: list[SmoothingSegment] = []
    bounds = sorted({0, time_tai_ns.size, *(int(b) for b in breaks if 0 < b < time_tai_ns.size)})
    pieces = [slice(a + s.start, a + s.stop) for a, b in zip(bounds[:-1], bounds[1:], strict=True)
              for s in split_segments(time_tai_ns[a:b], segment_max_s, max_gap_s)]
    for sl in pieces:
        n = sl.stop - sl.start
        if n < MIN_SMOOTHING_SAMPLES:
            segs.append(SmoothingSegment(sl.start, sl.stop, (-1, -1, -1), np.full(3, np.nan)))
            continue
        t_s = (time_tai_ns[sl] - time_tai_ns[sl.start]).astype(np.float64) / NS_PER_S
        q_c = mean_quaternion(q[sl])
        z = residual_mrps(q[sl], q_c)
        z_fit = np.empty_like(z)
        ms = []
        for i in range(3):
            z_fit[:, i], m = fit_trend_sines(t_s, z[:, i], trend_degree=trend_degree, harmonics=harmonics)
            ms.append(m)
        out[sl] = rotations.quat_multiply(q_c, rotations.mrp_to_quat(z_fit))
        resid = sensor_axis_residuals(z, z_fit)
        dof = np.maximum(n - (np.asarray(ms) + trend_degree + 1), 1)
        segs.append(SmoothingSegment(sl.start, sl.stop, (ms[0], ms[1], ms[2]),
                                     np.sqrt(np.sum(resid ** 2, axis=0) / dof)))
    return rotations.quat_canonical(out), tuple(segs)


def orbital_attitude(
    time_tai_ns: ArrayLike,
    q_XS: ArrayLike,
    gnss_time_tai_ns: ArrayLike,
    r_E: ArrayLike,
    v_E: ArrayLike,
    *,
    q_BS: ArrayLike = (1.0, 0.0, 0.0, 0.0),
    inertial_frame: str = "GCRF",
    orbital_frame: str = "orbital_003",
    smoothing: bool = True,
    smoothing_frame: SmoothingFrame = "orbital",
    harmonics: int | None = None,
    trend_degree: int = 3,
    eop: EopSource = None,
    gnss_method: Literal["chebyshev", "sine"] = "chebyshev",
    segment_max_s: float = SEGMENT_MAX_S,
    max_gap_s: float = 60.0,
    euler_sequence: EulerSequence = "231",
    segment_at_manoeuvres: bool = True,
    gnss_position_sigma_m: float | None = None,
    gnss_velocity_sigma_m_s: float | None = None,
    drop_late_gnss_tags: bool = True,
    progress: Callable[[float, str], None] | None = None,
) -> OrbitalAttitude:
    """Pitch, yaw, roll of 003 §1.6 (module docstring) from star-tracker and GNSS telemetry.

    time_tai_ns (N,) int64 sorted; q_XS (N, 4) sensor -> ``inertial_frame`` quaternions, scalar
    first; gnss_time_tai_ns (K,), r_E, v_E (K, 3) ITRF [m, m/s]; q_BS (4,) mounting (sensor ->
    body); eop: EarthOrientation, a callable tai_ns -> EarthOrientation, or None (zero).
    Star-tracker samples outside the GNSS arcs are dropped (listed in ``dropped_tai_ns``).
    euler_sequence: of the reported angles (EULER_SEQUENCES). segment_at_manoeuvres: smoothing segments
    start and end at the manoeuvres found in q_OS (:func:`detect_manoeuvres`). The GNSS fit is judged
    against the receiver noise (given, or estimated from the samples: processing.orbits.gnss_checks
    .check_gnss_fit); its error passes into ``orbit_frame_sigma_rad``. drop_late_gnss_tags: when the check
    finds states whose residuals are a time shift (late tags), the orbit is fitted again without them
    (``gnss_check`` keeps the first check, ``gnss_dropped_late`` counts them, ``gnss_recheck`` judges the refit).
    """
    report = progress or (lambda f, s: None)
    t, q, frame, q_BS_arr = _checked_inputs(time_tai_ns, q_XS, q_BS, inertial_frame, orbital_frame, smoothing_frame,
                                            euler_sequence)
    report(0.1, "GNSS orbit fit")
    fit, gnss_check, recheck, n_late = _checked_gnss_fit(
        gnss_time_tai_ns, r_E, v_E, method=gnss_method, position_sigma_m=gnss_position_sigma_m,
        velocity_sigma_m_s=gnss_velocity_sigma_m_s, drop_late_tags=drop_late_gnss_tags)
    frame_check = recheck or gnss_check
    covered = fit.covered(t)
    if not np.any(covered):
        raise OrbitalAttitudeError("no star-tracker sample lies within the GNSS arcs (the two streams do not "
                                   "overlap in time)")
    report(0.3, "frames")
    fr = _frames(t, q, covered, fit, frame, orbital_frame, eop)  # 1-3
    q_SB = rotations.quat_conjugate(q_BS_arr)
    q_OB_raw = rotations.quat_canonical(rotations.quat_multiply(fr.q_OS, q_SB))
    segments: tuple[SmoothingSegment, ...] = ()
    q_OB = q_OB_raw
    man = detect_manoeuvres(fr.time_tai_ns, fr.q_OS, max_gap_s=max_gap_s) if segment_at_manoeuvres else []
    if smoothing:  # 4
        report(0.5, "smoothing (003 §1.3)")
        breaks = tuple(i for ab in man for i in ab)
        q_OS, segments = _smoothed_q_OS(fr, smoothing_frame, harmonics=harmonics, trend_degree=trend_degree,
                                        segment_max_s=segment_max_s, max_gap_s=max_gap_s, breaks=breaks)
        q_OB = rotations.quat_canonical(rotations.quat_multiply(q_OS, q_SB))
    report(0.8, "angles and ascending nodes")  # 5
    pitch, yaw, roll = euler_angles(q_OB, euler_sequence)
    pitch_raw, yaw_raw, roll_raw = euler_angles(q_OB_raw, euler_sequence)
    nodes = ascending_nodes(fit, eop)
    since = time_since_ascending_node_s(fr.time_tai_ns, fr.r_I, fr.v_I, nodes)
    q_GB = rotations.quat_canonical(rotations.quat_multiply(fr.q_GO, q_OB))
    return OrbitalAttitude(
        time_tai_ns=fr.time_tai_ns, q_GB=q_GB, q_OB=q_OB, pitch_rad=pitch, yaw_rad=yaw, roll_rad=roll,
        pitch_raw_rad=pitch_raw, yaw_raw_rad=yaw_raw, roll_raw_rad=roll_raw, time_since_node_s=since,
        ascending_nodes_tai_ns=nodes, r_I=fr.r_I, v_I=fr.v_I, dropped_tai_ns=fr.dropped_tai_ns, gnss=fit,
        inertial_frame=frame, orbital_frame=orbital_frame, smoothing=smoothing, smoothing_frame=smoothing_frame,
        segments=segments, euler_sequence=euler_sequence, q_OB_raw=q_OB_raw,
        manoeuvres_tai_ns=tuple((int(fr.time_tai_ns[a]), int(fr.time_tai_ns[b - 1])) for a, b in man),
        gnss_check=gnss_check, orbit_frame_sigma_rad=_orbit_frame_sigma(frame_check, fr.r_I, fr.v_I),
        gnss_recheck=recheck, gnss_dropped_late=n_late,
        attitude_sigma_rad=_attitude_sigma(segments, q_BS_arr, fr.time_tai_ns.size) if smoothing else None,
    )


def _checked_gnss_fit(
    gnss_time_tai_ns: ArrayLike, r_E: ArrayLike, v_E: ArrayLike, *, method: Literal["chebyshev", "sine"],
    position_sigma_m: float | None, velocity_sigma_m_s: float | None, drop_late_tags: bool,
) -> tuple[GnssFit, GnssFitCheck, GnssFitCheck | None, int]:
    """Step 2's GNSS fit and its check; when the check finds late tags (and ``drop_late_tags``), the fit
    again without them and its check. Returns (fit used, first check, recheck or None, number dropped)."""
    fit = fit_gnss(gnss_time_tai_ns, r_E, v_E, method=method)
    gnss_check = check_gnss_fit(fit, gnss_time_tai_ns, r_E, v_E, position_sigma_m=position_sigma_m,
                                velocity_sigma_m_s=velocity_sigma_m_s)
    recheck = None
    n_late = 0
    if drop_late_tags and not gnss_check.consistent and np.any(gnss_check.late_tags):
        keep = ~gnss_check.late_tags
        n_late = int(gnss_check.late_tags.sum())
        tg, rg, vg = (np.asarray(x)[keep] for x in (gnss_time_tai_ns, r_E, v_E))
        fit = fit_gnss(tg, rg, vg, method=method)
        recheck = check_gnss_fit(fit, tg, rg, vg, position_sigma_m=position_sigma_m,
                                 velocity_sigma_m_s=velocity_sigma_m_s)
    return fit, gnss_check, recheck, n_late


def _orbit_frame_sigma(chk: GnssFitCheck, r_I: NDArray, v_I: NDArray) -> NDArray:
    """(pitch, yaw, roll) error [rad] of the orbital frame from the GNSS fit's error (per axis) e_r, e_v: the
    radius direction tilts by e_r / r about axes 1 and 2 (roll, pitch), the orbit normal by e_v / v + e_r / r
    about axes 1 and 3 (roll, yaw); root-sum-square where both act."""
    tilt = chk.position_error_m / float(np.median(np.linalg.norm(r_I, axis=1)))
    normal = chk.velocity_error_m_s / float(np.median(np.linalg.norm(v_I, axis=1))) + tilt
    return np.array([tilt, normal, float(np.hypot(tilt, normal))])


def _attitude_sigma(segments: tuple[SmoothingSegment, ...], q_BS: NDArray, n: int) -> NDArray | None:
    """(pitch, yaw, roll) star-tracker part [rad]: the smoothing residual rms per sensor axis, times
    sqrt(parameters / samples) of each segment (the error of the fitted curve), pooled over the segments
    and taken to the body axes through the mounting (body axes 2, 3, 1 ~ pitch, yaw, roll near the
    orbital orientation). None when no segment was smoothed."""
    seg = [s for s in segments if s.smoothed]
    if not seg:
        return None
    var_S = np.zeros(3)
    for s in seg:
        m = s.stop - s.start
        p = np.asarray(s.harmonics, dtype=float) + 4.0
        var_S += m * s.residual_rms_rad ** 2 * np.minimum(p / m, 1.0)
    var_S /= sum(s.stop - s.start for s in seg)
    dcm = rotations.quat_to_dcm(q_BS)
    var_B = (dcm ** 2) @ var_S
    return np.sqrt(var_B[[1, 2, 0]])


def _checked_inputs(
    time_tai_ns: ArrayLike, q_XS: ArrayLike, q_BS: ArrayLike, inertial_frame: str, orbital_frame: str,
    smoothing_frame: str, euler_sequence: str,
) -> tuple[NDArray, NDArray, str, NDArray]:
    """(times (N,) int64, q_XS (N, 4), the canonical inertial frame name, unit q_BS) after the checks."""
    t = np.asarray(time_tai_ns, dtype=np.int64)
    q = np.asarray(q_XS, dtype=np.float64)
    if t.ndim != 1 or q.shape != (t.size, 4):
        raise OrbitalAttitudeError(f"expected times (N,) and quaternions (N, 4), got {t.shape} and {q.shape}")
    if t.size < 2:
        raise OrbitalAttitudeError(f"need at least 2 star-tracker samples, got {t.size}")
    if np.any(np.diff(t) <= 0):
        raise OrbitalAttitudeError("star-tracker times must be strictly increasing")
    frame = canonical_inertial_frame(inertial_frame)
    if orbital_frame not in ORBITAL_FRAMES:
        raise OrbitalAttitudeError(f"orbital_frame must be one of {', '.join(ORBITAL_FRAMES)}, got {orbital_frame!r}")
    if smoothing_frame not in ("orbital", "inertial"):
        raise OrbitalAttitudeError(f"smoothing_frame must be 'orbital' or 'inertial', got {smoothing_frame!r}")
    if euler_sequence not in EULER_SEQUENCES:
        raise OrbitalAttitudeError(f"euler_sequence must be one of {', '.join(EULER_SEQUENCES)}, "
                                   f"got {euler_sequence!r}")
    return t, q, frame, rotations.quat_normalize(np.asarray(q_BS, dtype=np.float64))


@dataclass(frozen=True)
class _Frames:
    """Steps 1-3 at the star-tracker samples inside the GNSS arcs (N): times, q_GS (sensor -> GCRS), GCRS
    state r_I, v_I, the orbital frame q_GO and q_OS = q_GO^-1 o q_GS; the samples dropped (outside)."""

    time_tai_ns: NDArray
    q_GS: NDArray
    r_I: NDArray
    v_I: NDArray
    q_GO: NDArray
    q_OS: NDArray
    dropped_tai_ns: NDArray


def _frames(
    t: NDArray, q: NDArray, covered: NDArray, fit: GnssFit, frame: str, orbital_frame: str, eop: EopSource
) -> _Frames:
    """Steps 1-3 on the samples ``covered`` by the GNSS arcs: star tracker to the GCRS, the smoothed GNSS
    orbit in the GCRS, the orbital frame."""
    dropped = t[~covered]
    t, q = t[covered], rotations.quat_normalize(q[covered])
    eop_t = eop(t) if callable(eop) else (eop or EarthOrientation())
    q_GX = rotations.dcm_to_quat(inertial_to_gcrs_mat(frame, t, eop_t))
    q_GS = rotations.quat_multiply(q_GX, q)
    r_I, v_I, _ = gnss_to_gcrs(fit, t, eop_t)
    q_GO = _q_GO(r_I, v_I, orbital_frame)
    q_OS = rotations.quat_multiply(rotations.quat_conjugate(q_GO), q_GS)
    return _Frames(t, q_GS, r_I, v_I, q_GO, q_OS, dropped)


def _smoothed_q_OS(
    fr: _Frames, smoothing_frame: str, **options: Any
) -> tuple[NDArray, tuple[SmoothingSegment, ...]]:
    """Step 4: q_OS smoothed by 003 §1.3 in the orbital frame, or q_GS smoothed (003) and taken to O."""
    if smoothing_frame == "orbital":
        return smooth_attitude(fr.time_tai_ns, fr.q_OS, **options)
    q_GS_sm, segments = smooth_attitude(fr.time_tai_ns, fr.q_GS, **options)
    return rotations.quat_multiply(rotations.quat_conjugate(fr.q_GO), q_GS_sm), segments
