"""Direction of the GNSS antenna axis in the orbital frame from which navigation satellites are tracked
(002, eqs. 5-7; Belokonov & Kramlikh 2007).

The receiver reports the satellites it tracks ("visible"); the others of the constellation, whose
positions come from the broadcast ephemerides, are "invisible". With g_i the unit line of sight from
the spacecraft to satellite i in the orbital frame O of 002 (Z2 along the radius vector, Y2 along the
orbital angular momentum, X2 = Y2 x Z2 completes; the frame of ``orbital_frames.dcm_IO_003``), an
antenna of cone half-angle alpha about the unit axis a should see (eq. 5)

    g_i . a >= cos(alpha) for visible i,    g_j . a < cos(alpha) for invisible j.

Invisible satellites hidden by the Earth tell nothing about the antenna and are dropped (eq. 6): with
z the Z2 component of g, the Earth disc seen from radius r has angular radius arcsin(R / r), so j is
occulted when z < 0 and |z| > cos(arcsin(R / r)) (R may include a grazing altitude for the atmosphere).
The axis minimises (eq. 7)

    Phi(a) = sum_visible (g_i . a - 1)^2 + sum_invisible (g_j . a + 1)^2,

whose normal equations are the 3x3 linear system printed in the paper:
(sum_all g g^T) a = sum_visible g - sum_invisible g. The solution is normalised to a unit vector.
alpha is not used by eq. 7 itself; it is the parameter of eq. 5, against which the solution is
checked (``n_violations``: satellites on the wrong side of the cone).

Everything is vectorised over epochs (T) and satellites (S); masks select what is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.frames.orbital import dcm_IO_003
from processing.units import OMEGA_EARTH_RAD_S, R_EARTH_M

DEFAULT_CONE_HALF_ANGLE_RAD = np.deg2rad(80.0)
"""A hemispherical patch antenna with a 10 deg elevation mask."""
DEFAULT_GRAZING_ALTITUDE_M = 50e3
"""Rays passing lower than this over the surface are taken as blocked (troposphere, ionosphere)."""
MIN_SATELLITES = 4
MAX_CONDITION = 1e6


class AntennaAxisError(ValueError):
    """Arrays of inconsistent shapes."""


def dcm_EO_002(r_E: ArrayLike, v_E: ArrayLike, omega_rad_s: float = OMEGA_EARTH_RAD_S) -> NDArray[np.float64]:
    """Orbital frame of 002 (Z2 radial, Y2 orbital angular momentum, X2 = Y2 x Z2) in ITRF coordinates.

    r_E, v_E: (..., 3) Earth-fixed position (m) and velocity relative to the Earth (m/s). The angular
    momentum is that of the inertial motion: v_inertial = v_E + w x r_E with w along the ITRF z axis
    (polar motion neglected: < 1e-6 rad). Returns dcm_EO (..., 3, 3): v_E = dcm_EO @ v_O.
    """
    r = np.asarray(r_E, dtype=np.float64)
    v = np.asarray(v_E, dtype=np.float64)
    w = np.array([0.0, 0.0, omega_rad_s])
    return dcm_IO_003(r, v + np.cross(w, r))


def line_of_sight_O(r_sat_E: ArrayLike, r_E: ArrayLike, dcm_EO: ArrayLike) -> NDArray[np.float64]:
    """Unit lines of sight g (T, S, 3) in frame O from the spacecraft (T, 3) to satellites (T, S, 3), ITRF.

    NaN where the satellite position is NaN.
    """
    rs = np.asarray(r_sat_E, dtype=np.float64)
    r = np.asarray(r_E, dtype=np.float64)
    m = np.asarray(dcm_EO, dtype=np.float64)
    if rs.ndim != 3 or r.shape != (rs.shape[0], 3) or m.shape != (rs.shape[0], 3, 3):
        raise AntennaAxisError(f"expected r_sat_E (T, S, 3), r_E (T, 3), dcm_EO (T, 3, 3); got {rs.shape}, "
                               f"{r.shape}, {m.shape}")
    d = rs - r[:, None, :]
    with np.errstate(invalid="ignore"):
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.einsum("tji,tsj->tsi", m, d)


def earth_occulted(g_O: ArrayLike, radius_m: ArrayLike, grazing_altitude_m: float = DEFAULT_GRAZING_ALTITUDE_M
                   ) -> NDArray[np.bool_]:
    """Eq. 6: the line of sight g (T, S, 3) passes through the Earth (plus grazing altitude) seen from
    radius_m (T,): z < 0 and |z| > cos(arcsin((R + h) / r)). Returns (T, S) bool (False for NaN g)."""
    g = np.asarray(g_O, dtype=np.float64)
    r = np.asarray(radius_m, dtype=np.float64)
    ratio = np.clip((R_EARTH_M + grazing_altitude_m) / r, 0.0, 1.0)
    limit = np.cos(np.arcsin(ratio))[:, None]
    z = g[..., 2]
    with np.errstate(invalid="ignore"):
        return (z < 0) & (np.abs(z) > limit)


@dataclass(frozen=True)
class AntennaAxisResult:
    """Antenna axis per epoch (eq. 7).

    a_O: (T, 3) unit axis in frame O, NaN where not determined (``ok`` False).
    n_visible, n_invisible, n_occulted: (T,) counts used / invisible used / invisible dropped by eq. 6.
    n_violations: (T,) satellites used that violate eq. 5 for the cone half-angle.
    residual_rms: (T,) sqrt(Phi / n_used) of eq. 7 at the unnormalised minimum.
    condition: (T,) condition number of the normal matrix sum g g^T.
    ok: (T,) at least MIN_SATELLITES used, one of them visible, condition <= MAX_CONDITION.
    """

    a_O: NDArray[np.float64]
    n_visible: NDArray[np.int64]
    n_invisible: NDArray[np.int64]
    n_occulted: NDArray[np.int64]
    n_violations: NDArray[np.int64]
    residual_rms: NDArray[np.float64]
    condition: NDArray[np.float64]
    ok: NDArray[np.bool_]


def antenna_axis_O(g_O: ArrayLike, visible: ArrayLike, known: ArrayLike, radius_m: ArrayLike, *,
                   cone_half_angle_rad: float = DEFAULT_CONE_HALF_ANGLE_RAD,
                   grazing_altitude_m: float = DEFAULT_GRAZING_ALTITUDE_M) -> AntennaAxisResult:
    """Antenna axis in frame O from visibility (002, eqs. 5-7), vectorised over epochs.

    g_O: (T, S, 3) unit lines of sight in O (:func:`line_of_sight_O`); visible: (T, S) tracked by the
    receiver; known: (T, S) the satellite's position is known (ephemeris valid); radius_m: (T,)
    spacecraft geocentric radius. Visible satellites are used whatever eq. 6 says (the screening flags
    those that are geometrically impossible); invisible ones hidden by the Earth are dropped.
    """
    g = np.asarray(g_O, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    kn = np.asarray(known, dtype=bool) & np.isfinite(g).all(axis=-1)
    if g.ndim != 3 or g.shape[-1] != 3 or vis.shape != g.shape[:2] or kn.shape != g.shape[:2]:
        raise AntennaAxisError(f"expected g_O (T, S, 3), visible and known (T, S); got {g.shape}, {vis.shape}, "
                               f"{np.shape(known)}")
    occ = earth_occulted(g, radius_m, grazing_altitude_m)
    used_vis = vis & kn
    used_inv = ~vis & kn & ~occ
    sign = used_vis.astype(float) - used_inv.astype(float)  # +1 visible, -1 invisible, 0 dropped
    weight = np.abs(sign)
    gz = np.where(kn[..., None], g, 0.0)
    normal = np.einsum("ts,tsi,tsj->tij", weight, gz, gz)
    rhs = np.einsum("ts,tsi->ti", sign, gz)
    n_used = weight.sum(axis=1)
    cond = np.linalg.cond(normal)
    ok = (n_used >= MIN_SATELLITES) & used_vis.any(axis=1) & (cond <= MAX_CONDITION)
    safe = np.where(ok[:, None, None], normal, np.eye(3))
    x = np.linalg.solve(safe, rhs[..., None])[..., 0]
    fit = np.einsum("tsi,ti->ts", gz, x)
    phi = (weight * (fit - sign) ** 2).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = x / np.linalg.norm(x, axis=-1, keepdims=True)
        rms = np.sqrt(phi / n_used)
    a = np.where(ok[:, None], a, np.nan)
    cos_a = np.cos(cone_half_angle_rad)
    dot = np.einsum("tsi,ti->ts", gz, np.nan_to_num(a))
    violations = (used_vis & (dot < cos_a)) | (used_inv & (dot >= cos_a))
    return AntennaAxisResult(
        a_O=a, n_visible=used_vis.sum(axis=1), n_invisible=used_inv.sum(axis=1),
        n_occulted=(~vis & kn & occ).sum(axis=1), n_violations=np.where(ok, violations.sum(axis=1), 0),
        residual_rms=np.where(ok, rms, np.nan), condition=cond, ok=ok,
    )


def refine_antenna_axis_O(g_O: ArrayLike, visible: ArrayLike, used: ArrayLike, a0_O: ArrayLike,
                          cone_half_angle_rad: float = DEFAULT_CONE_HALF_ANGLE_RAD, *, softness: float = 0.05,
                          iterations: int = 15, max_step_rad: float = 0.2) -> NDArray[np.float64]:
    """Refine the eq. 7 axis with the cone of eq. 5: maximum-likelihood fit of a soft cone (beyond 002).

    Eq. 7 asks the projections g . a to equal +-1, which no axis can satisfy, and its solution is
    pulled towards the mean of the visible directions. Eq. 5 only asks them to lie on the right side
    of cos(alpha). Here P(visible) = 1 / (1 + exp(-(g . a - cos alpha) / softness)) and the unit axis
    maximising the likelihood of the observed visibility is found by Newton steps in the tangent plane
    of the sphere, started from a0 (eq. 7) and limited to max_step_rad per step. On the seed-002
    scenario (GPS only, alpha = 80 deg) this halves the median error of eq. 7 (about 6 deg against 13).

    g_O: (T, S, 3) unit lines of sight; visible: (T, S); used: (T, S) satellites taken into account
    (known, and for invisible ones not hidden by the Earth); a0_O: (T, 3). Returns (T, 3) unit axes
    (NaN where a0 is NaN).
    """
    g = np.nan_to_num(np.asarray(g_O, dtype=np.float64))
    y = np.where(np.asarray(visible, dtype=bool), 1.0, -1.0)
    use = np.asarray(used, dtype=bool).astype(float)
    a = np.asarray(a0_O, dtype=np.float64).copy()
    bad = ~np.isfinite(a).all(axis=1)
    a[bad] = [1.0, 0.0, 0.0]
    c = np.cos(cone_half_angle_rad)
    eye = np.eye(3)
    for _ in range(iterations):
        s = (np.einsum("tsi,ti->ts", g, a) - c) / softness
        p_wrong = 0.5 * (1.0 - np.tanh(0.5 * y * s))  # 1 / (1 + exp(y s)), overflow-free
        grad = np.einsum("ts,tsi->ti", -y * p_wrong * use, g) / softness
        curv = 0.25 * (1.0 - np.tanh(0.5 * s) ** 2) * use  # sigma(s) sigma(-s)
        hess = np.einsum("ts,tsi,tsj->tij", curv, g, g) / softness**2
        proj = eye - a[:, :, None] * a[:, None, :]
        h_t = proj @ hess @ proj + a[:, :, None] * a[:, None, :] + 1e-9 * eye
        d = np.linalg.solve(h_t, -(proj @ grad[..., None]))[..., 0]
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(norm > max_step_rad, d * (max_step_rad / np.maximum(norm, 1e-300)), d)
        a = a + d
        a = a / np.linalg.norm(a, axis=1, keepdims=True)
    a[bad] = np.nan
    return a
