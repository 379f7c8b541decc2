"""Earth orientation: GCRS <-> ITRS rotation matrices and state transforms, IAU 2006/2000A via ERFA.

Everything is vectorised: pyerfa broadcasts over arrays, so a (N,) array of times gives (N, 3, 3)
matrices without Python loops. Times are int64 ``tai_ns`` (ns since 1970-01-01T00:00:00 TAI);
the TT and UT1 two-part Julian dates come from :mod:`processing.time.timescales`.

Conventions: ``dcm_EI`` maps GCRS (I) coordinates to ITRS (E) coordinates, r_E = dcm_EI @ r_I;
it is ERFA's ``rc2t`` = RPOM * R3(ERA) * RC2I (IERS Conventions 2010, eq. 5.1, CIO based).

Earth orientation parameters (UT1-UTC, polar motion) default to zero; the ``source`` string of
:class:`EarthOrientation` says which were used so that reports can print it. Without EOP the
rotation is in error by up to 0.9 s of UT1 (~6.6e-5 rad about the pole, ~470 m at the 7200 km
radius of an 830 km orbit) and by the polar motion (~0.5 arcsec, ~17 m). CIP offsets dX, dY (< 1 mas) are not applied.
Tabulated EOP (IERS finals2000A) are interpolated into an EarthOrientation by processing.frames.eop.

Also here (second half of the module): the inertial frames star trackers and CCSDS messages use
besides the GCRF -- EME2000 (frame bias), MOD, TOD (IAU 2006/2000A, equinox based) and TEME
(GMST 1982, Vallado et al. 2006) -- as ``gcrs_to_inertial_mat(frame, tai_ns)`` and state transforms
between any of them and the ITRS.
"""

from __future__ import annotations

from dataclasses import dataclass

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.time.julian_dates import tai_ns_to_jd, tai_ns_to_ut1_jd
from processing.units import OMEGA_EARTH_RAD_S

earth_rotation_rate_rad_s = OMEGA_EARTH_RAD_S
"""Alias of :data:`OMEGA_EARTH_RAD_S`."""


class FrameInputError(ValueError):
    """Frame-transform input of the wrong shape."""


@dataclass(frozen=True)
class EarthOrientation:
    """Earth orientation parameters for the celestial-terrestrial transformation.

    dut1_s : UT1 - UTC [s], scalar or per-sample array broadcastable against the times.
    xp_rad, yp_rad : polar motion (coordinates of the CIP in the ITRS) [rad], same broadcasting.
    source : free text naming where the values came from, printed by reports.
    """

    dut1_s: float | NDArray = 0.0
    xp_rad: float | NDArray = 0.0
    yp_rad: float | NDArray = 0.0
    source: str = "zero (no EOP supplied)"


def _tt_ut1(tai_ns: ArrayLike, eop: EarthOrientation) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    tt1, tt2 = tai_ns_to_jd(tai_ns, scale="tt")
    ut1, ut2 = tai_ns_to_ut1_jd(tai_ns, dut1_s=eop.dut1_s)
    return tt1, tt2, ut1, ut2


def gcrs_to_itrs_mat_jd(
    tt1: ArrayLike, tt2: ArrayLike, ut1: ArrayLike, ut2: ArrayLike, xp_rad: ArrayLike, yp_rad: ArrayLike
) -> NDArray:
    """dcm_EI (..., 3, 3) from two-part TT and UT1 Julian dates and polar motion (erfa.c2t06a)."""
    return np.asarray(erfa.c2t06a(tt1, tt2, ut1, ut2, xp_rad, yp_rad))


def gcrs_to_itrs_mat(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """Rotation matrix dcm_EI mapping GCRS coordinates to ITRS coordinates.

    tai_ns : (...) int64 ns since 1970-01-01T00:00:00 TAI.
    eop : Earth orientation parameters (default: all zero).
    Returns (..., 3, 3): r_E = dcm_EI @ r_I. IAU 2006 precession, IAU 2000A nutation, CIO based
    (ERFA c2t06a, IERS Conventions 2010 ch. 5).
    """
    eop = EarthOrientation() if eop is None else eop
    tt1, tt2, ut1, ut2 = _tt_ut1(tai_ns, eop)
    return gcrs_to_itrs_mat_jd(tt1, tt2, ut1, ut2, eop.xp_rad, eop.yp_rad)


def itrs_to_gcrs_mat(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """dcm_IE (..., 3, 3) = transpose of :func:`gcrs_to_itrs_mat`: r_I = dcm_IE @ r_E."""
    return np.swapaxes(gcrs_to_itrs_mat(tai_ns, eop), -1, -2)


def _dcm_EI_and_omega_E(tai_ns: ArrayLike, eop: EarthOrientation) -> tuple[NDArray, NDArray]:
    """dcm_EI (..., 3, 3) and the Earth's angular velocity in ITRS coordinates (..., 3) [rad/s].

    The Earth rotates about the CIP, which is the z axis of the TIRS; in the ITRS it is
    RPOM @ (0, 0, w) (ERFA pom00 with the TIO locator s' of sp00), RPOM being the last factor of
    dcm_EI = RPOM R3(ERA) RC2I.
    """
    tt1, tt2, ut1, ut2 = _tt_ut1(tai_ns, eop)
    dcm_EI = gcrs_to_itrs_mat_jd(tt1, tt2, ut1, ut2, eop.xp_rad, eop.yp_rad)
    rpom = np.asarray(erfa.pom00(eop.xp_rad, eop.yp_rad, erfa.sp00(tt1, tt2)))
    return dcm_EI, OMEGA_EARTH_RAD_S * rpom[..., :, 2]


def _check_vectors(tai_ns: ArrayLike, *vectors: ArrayLike) -> tuple[NDArray, ...]:
    t_shape = np.shape(tai_ns)
    out = []
    for vec in vectors:
        arr = np.asarray(vec, dtype=float)
        if arr.shape[-1:] != (3,):
            raise FrameInputError(f"expected vectors of shape (..., 3), got {arr.shape}")
        try:
            np.broadcast_shapes(arr.shape[:-1], t_shape)
        except ValueError as exc:
            raise FrameInputError(
                f"vector shape {arr.shape} does not match times of shape {t_shape} (expected {t_shape + (3,)})"
            ) from exc
        out.append(arr)
    return tuple(out)


def gcrs_to_itrs_state(
    r_I: ArrayLike, v_I: ArrayLike, tai_ns: ArrayLike, eop: EarthOrientation | None = None
) -> tuple[NDArray, NDArray]:
    """Transform a GCRS position/velocity to ITRS (Earth-fixed, velocity relative to the Earth).

    r_I, v_I : (..., 3) [m], [m/s] GCRS; tai_ns : (...) int64.
    Returns r_E = R r_I and v_E = R v_I - omega_E x r_E, with R = dcm_EI and omega_E the Earth's
    angular velocity along the CIP (TIRS z axis), expressed in the ITRS (polar motion is included in
    its direction; taking it along the ITRS z axis instead would err by w |r| |polar motion|, 1.8e-3
    m/s for 0.7 arcsec). Neglected: the rate of precession-nutation and of the CIO locator (at most
    8.5e-12 rad/s over 2000-2010 by differencing erfa.c2i06a: 6.8e-5 m/s at |r| = 8000 km), the rate
    of polar motion (~2e-13 rad/s, ~2e-6 m/s), length-of-day variations of the rotation rate (~3e-8
    relative, < 2e-5 m/s) and the 1.5e-13 rad/s between OMEGA_EARTH_RAD_S and the ERA rate (~1e-6
    m/s). Together below 1e-4 m/s for |r| < 8000 km, a tenth of the 1 mm/s GNSS velocity error of
    003 §1.6.
    """
    eop = EarthOrientation() if eop is None else eop
    r_arr, v_arr = _check_vectors(tai_ns, r_I, v_I)
    dcm_EI, omega_E = _dcm_EI_and_omega_E(tai_ns, eop)
    r_E = np.einsum("...ij,...j->...i", dcm_EI, r_arr)
    v_E = np.einsum("...ij,...j->...i", dcm_EI, v_arr) - np.cross(omega_E, r_E)
    return r_E, v_E


def itrs_to_gcrs_state(
    r_E: ArrayLike, v_E: ArrayLike, tai_ns: ArrayLike, eop: EarthOrientation | None = None
) -> tuple[NDArray, NDArray]:
    """Inverse of :func:`gcrs_to_itrs_state`: r_I = R^T r_E, v_I = R^T (v_E + omega_E x r_E).

    r_E, v_E : (..., 3) [m], [m/s] ITRS (velocity relative to the rotating Earth); tai_ns : (...).
    Same neglected terms as the forward transform; the two are exact inverses of each other.
    """
    eop = EarthOrientation() if eop is None else eop
    r_arr, v_arr = _check_vectors(tai_ns, r_E, v_E)
    dcm_EI, omega_E = _dcm_EI_and_omega_E(tai_ns, eop)
    v_rot = v_arr + np.cross(omega_E, r_arr)
    r_I = np.einsum("...ji,...j->...i", dcm_EI, r_arr)
    v_I = np.einsum("...ji,...j->...i", dcm_EI, v_rot)
    return r_I, v_I


def gmst_rad(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """Greenwich mean sidereal time [rad, 0..2pi), IAU 2006 (erfa.gmst06), consistent with c2t06a.

    tai_ns : (...) int64; only eop.dut1_s is used. This is the S(t) of 003 §1.6 in the modern
    (IAU 2006) form.
    """
    eop = EarthOrientation() if eop is None else eop
    tt1, tt2, ut1, ut2 = _tt_ut1(tai_ns, eop)
    return np.asarray(erfa.gmst06(ut1, ut2, tt1, tt2))


def era_rad(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """Earth rotation angle [rad, 0..2pi), IAU 2000 (erfa.era00); only eop.dut1_s is used."""
    eop = EarthOrientation() if eop is None else eop
    ut1, ut2 = tai_ns_to_ut1_jd(tai_ns, dut1_s=eop.dut1_s)
    return np.asarray(erfa.era00(ut1, ut2))


# ---------------------------------------------------------------------------------------------
# Inertial frames "of date" and EME2000 (issue 6): MOD, TOD, TEME, EME2000 relative to the GCRS.
#
# Star trackers and older tools give attitude in these frames; CCSDS messages name them
# (SANA reference-frame registry: GCRF, ICRF, EME2000, J2000, MOD, TOD, TEME). Every matrix here
# is ``dcm_XG``: r_X = dcm_XG @ r_G for a frame X and G = GCRS, (..., 3, 3) for times (...).
#
# - EME2000 (= J2000, mean dynamical equator and equinox of J2000.0): the constant IAU 2006 frame
#   bias, r_EME2000 = RB r_GCRS (ERFA bp06 "rb"; ~23 mas, 0.7 m at LEO radius).
# - MOD (mean equator and equinox of date): bias-precession, IAU 2006 (ERFA pmat06 = bp06 "rbp").
#   This is the X1X2X3 of paper 003 (§1, §1.6: "second geoequatorial system of the epoch of date").
# - TOD (true equator and equinox of date): bias-precession-nutation, IAU 2006/2000A (ERFA
#   pnm06a), equinox based. CIP offsets dX, dY (< 1 mas) are not applied, as elsewhere here.
# - TEME (true equator, mean equinox; the frame of SGP4/TLEs): r_PEF = R3(GMST82) r_TEME and
#   r_ITRS = W r_PEF (Vallado, Crawford, Hujsak & Kelso 2006, "Revisiting Spacetrack Report #3",
#   AIAA 2006-6753, eq. for teme2ecef), with GMST of IAU 1982 (ERFA gmst82). The pseudo-Earth-fixed
#   frame is taken to be the TIRS of the CIO chain, so r_TEME = R3(ERA - GMST82) RC2I r_GCRS;
#   r_ITRS = RPOM R3(GMST82) r_TEME then holds exactly (RPOM with the TIO locator s', < 1e-10 rad
#   away from Vallado's W). TEME depends on UT1 only through ERA - GMST82 (precession in right
#   ascension, 7e-12 rad per second of UT1 error): negligible, so EOP may be omitted for it.
#
# Rates: these frames turn relative to the GCRS at the precession-nutation rate (< 1e-11 rad/s,
# < 1e-4 m/s at LEO radius), which the state transforms below neglect (as gcrs_to_itrs_state does).

INERTIAL_FRAMES = ("GCRF", "EME2000", "MOD", "TOD", "TEME")
"""Inertial frames known to :func:`gcrs_to_inertial_mat` (canonical names)."""

FRAME_ALIASES = {
    "GCRF": "GCRF", "GCRS": "GCRF", "ICRF": "GCRF", "ICRS": "GCRF",
    "EME2000": "EME2000", "J2000": "EME2000", "EME2000.0": "EME2000",
    "MOD": "MOD", "MEME": "MOD", "TOD": "TOD", "TETE": "TOD", "TEME": "TEME",
}
"""Names (CCSDS/SANA and astropy spellings) -> canonical inertial frame. ICRF axes are taken as
the GCRS axes (they differ only by the origin, irrelevant to directions and to geocentric states
at this accuracy)."""


class UnknownFrameError(ValueError):
    """A frame name that is not one of the supported inertial frames."""


def canonical_inertial_frame(name: str) -> str:
    """Canonical name (one of :data:`INERTIAL_FRAMES`) of an inertial frame name; ValueError otherwise."""
    key = str(name).strip().upper()
    if key not in FRAME_ALIASES:
        raise UnknownFrameError(
            f"unknown inertial frame {name!r}; expected one of {', '.join(sorted(FRAME_ALIASES))}"
        )
    return FRAME_ALIASES[key]


def gmst82_rad(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """Greenwich mean sidereal time of IAU 1982 [rad, 0..2pi) (erfa.gmst82), used by TEME.

    tai_ns : (...) int64; only eop.dut1_s is used.
    """
    eop = EarthOrientation() if eop is None else eop
    ut1, ut2 = tai_ns_to_ut1_jd(tai_ns, dut1_s=eop.dut1_s)
    return np.asarray(erfa.gmst82(ut1, ut2))


def gcrs_to_eme2000_mat(tai_ns: ArrayLike | None = None) -> NDArray:
    """dcm_JG (3, 3) or (..., 3, 3): the constant IAU 2006 frame bias RB, r_EME2000 = RB r_GCRS."""
    rb = np.asarray(erfa.bp06(2451545.0, 0.0)[0])
    if tai_ns is None:
        return rb
    return np.broadcast_to(rb, np.shape(tai_ns) + (3, 3)).copy()


def gcrs_to_mod_mat(tai_ns: ArrayLike) -> NDArray:
    """dcm_MG (..., 3, 3): GCRS -> mean equator and equinox of date, IAU 2006 (erfa.pmat06)."""
    tt1, tt2 = tai_ns_to_jd(tai_ns, scale="tt")
    return np.asarray(erfa.pmat06(tt1, tt2))


def gcrs_to_tod_mat(tai_ns: ArrayLike) -> NDArray:
    """dcm_TG (..., 3, 3): GCRS -> true equator and equinox of date, IAU 2006/2000A (erfa.pnm06a)."""
    tt1, tt2 = tai_ns_to_jd(tai_ns, scale="tt")
    return np.asarray(erfa.pnm06a(tt1, tt2))


def _rz(angle_rad: ArrayLike) -> NDArray:
    """Frame rotation about z, R3(a) = [[c, s, 0], [-s, c, 0], [0, 0, 1]] (..., 3, 3) (= erfa.rz)."""
    a = np.asarray(angle_rad, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, i = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, s, o], -1), np.stack([-s, c, o], -1), np.stack([o, o, i], -1)], -2)


def gcrs_to_teme_mat(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """dcm_EG (..., 3, 3) of TEME: r_TEME = R3(ERA - GMST82) RC2I r_GCRS (module notes above).

    tai_ns : (...) int64; eop: only dut1_s matters (and hardly: see the notes).
    """
    eop = EarthOrientation() if eop is None else eop
    tt1, tt2, ut1, ut2 = _tt_ut1(tai_ns, eop)
    rc2i = np.asarray(erfa.c2i06a(tt1, tt2))
    angle = np.asarray(erfa.era00(ut1, ut2)) - np.asarray(erfa.gmst82(ut1, ut2))
    return np.einsum("...ij,...jk->...ik", _rz(angle), rc2i)


def teme_to_itrs_mat(tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """dcm (..., 3, 3) with r_ITRS = RPOM R3(GMST82) r_TEME (Vallado et al. 2006, teme2ecef)."""
    eop = EarthOrientation() if eop is None else eop
    tt1, tt2, ut1, ut2 = _tt_ut1(tai_ns, eop)
    rpom = np.asarray(erfa.pom00(eop.xp_rad, eop.yp_rad, erfa.sp00(tt1, tt2)))
    return np.einsum("...ij,...jk->...ik", rpom, _rz(np.asarray(erfa.gmst82(ut1, ut2))))


def gcrs_to_inertial_mat(frame: str, tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """dcm_XG (..., 3, 3) from the GCRS to inertial frame ``frame`` (any name of FRAME_ALIASES).

    tai_ns : (...) int64. GCRF gives identity matrices.
    """
    name = canonical_inertial_frame(frame)
    if name == "GCRF":
        return np.broadcast_to(np.eye(3), np.shape(tai_ns) + (3, 3)).copy()
    if name == "EME2000":
        return gcrs_to_eme2000_mat(tai_ns)
    if name == "MOD":
        return gcrs_to_mod_mat(tai_ns)
    if name == "TOD":
        return gcrs_to_tod_mat(tai_ns)
    return gcrs_to_teme_mat(tai_ns, eop)


def inertial_to_gcrs_mat(frame: str, tai_ns: ArrayLike, eop: EarthOrientation | None = None) -> NDArray:
    """dcm_GX (..., 3, 3) = transpose of :func:`gcrs_to_inertial_mat`: r_GCRS = dcm_GX @ r_X."""
    return np.swapaxes(gcrs_to_inertial_mat(frame, tai_ns, eop), -1, -2)


def inertial_to_itrs_state(
    frame: str, r_X: ArrayLike, v_X: ArrayLike, tai_ns: ArrayLike, eop: EarthOrientation | None = None
) -> tuple[NDArray, NDArray]:
    """State in inertial frame ``frame`` -> ITRS (velocity relative to the rotating Earth).

    r_X, v_X : (..., 3) [m, m/s]; tai_ns : (...). Through the GCRS (:func:`gcrs_to_itrs_state`);
    the turning of X relative to the GCRS (< 1e-11 rad/s) is neglected.
    """
    r_arr, v_arr = _check_vectors(tai_ns, r_X, v_X)
    dcm_GX = inertial_to_gcrs_mat(frame, tai_ns, eop)
    r_G = np.einsum("...ij,...j->...i", dcm_GX, r_arr)
    v_G = np.einsum("...ij,...j->...i", dcm_GX, v_arr)
    return gcrs_to_itrs_state(r_G, v_G, tai_ns, eop)


def itrs_to_inertial_state(
    frame: str, r_E: ArrayLike, v_E: ArrayLike, tai_ns: ArrayLike, eop: EarthOrientation | None = None
) -> tuple[NDArray, NDArray]:
    """Inverse of :func:`inertial_to_itrs_state`: ITRS state -> inertial frame ``frame``."""
    r_G, v_G = itrs_to_gcrs_state(r_E, v_E, tai_ns, eop)
    dcm_XG = gcrs_to_inertial_mat(frame, tai_ns, eop)
    return np.einsum("...ij,...j->...i", dcm_XG, r_G), np.einsum("...ij,...j->...i", dcm_XG, v_G)
