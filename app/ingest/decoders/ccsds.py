"""Upload formats ``ccsds-aem`` (star_tracker) and ``ccsds-oem`` (gnss): CCSDS KVN messages.

The parsing is pure (processing/formats/ccsds_adm.py, ccsds_odm.py); here the messages are turned
into the canonical upload columns with the frames checked and converted:

- AEM (1.0 or 2.0): one of REF_FRAME_A / REF_FRAME_B must be an inertial frame (GCRF, ICRF,
  EME2000/J2000, MOD, TOD, TEME) and the other one the sensor or body; the quaternion is turned into
  q_IS (sensor -> inertial) whichever side the inertial frame is on, and frames of date or EME2000
  are converted to the GCRF (IAU 2006/2000A; TEME with zero UT1-UTC, which changes it by < 1e-9
  rad). All segments must name the same pair of frames.
- OEM (2.0 or 3.0): CENTER_NAME must be EARTH; ITRF states are taken as they are, inertial ones
  (GCRF, EME2000, MOD, TOD, TEME) are converted to the ITRF with zero EOP (the note says so: up to
  ~0.9 s of UT1 error, ~470 m along track at LEO, if the file's frame is inertial).
Times are passed on as TAI ISO strings, exact to the nanosecond.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from app.ingest.formats import Decoded, Decoder
from processing.attitude import rotations
from processing.formats.ccsds_adm import parse_aem
from processing.formats.ccsds_odm import is_earth_fixed, parse_oem
from processing.frames.earth_orientation import (
    UnknownFrameError,
    canonical_inertial_frame,
    inertial_to_gcrs_mat,
    inertial_to_itrs_state,
)
from processing.time import timescales


def _inertial(name: str) -> str | None:
    try:
        return canonical_inertial_frame(name)
    except UnknownFrameError:
        return None


def _times(t: np.ndarray) -> pa.Array:
    return pa.array(timescales.tai_ns_to_iso(t, "tai").tolist(), pa.string())


def decode_aem(body: bytes, stream: str) -> Decoded:
    aem = parse_aem(body)
    frames = {(s.ref_frame_a.upper(), s.ref_frame_b.upper()) for s in aem.segments}
    if len(frames) != 1:
        raise ValueError(f"all segments must use the same REF_FRAME_A/REF_FRAME_B; found {sorted(frames)}")
    frame_a, frame_b = next(iter(frames))
    inertial_a, inertial_b = _inertial(frame_a), _inertial(frame_b)
    if (inertial_a is None) == (inertial_b is None):
        raise ValueError(f"REF_FRAME_A = {frame_a} and REF_FRAME_B = {frame_b}: exactly one of them must be an "
                         "inertial frame (GCRF, ICRF, EME2000, J2000, MOD, TOD, TEME), the other the sensor/body")
    inertial = inertial_a or inertial_b
    assert inertial is not None
    sensor_frame = frame_b if inertial_a else frame_a
    t = np.concatenate([s.time_tai_ns for s in aem.segments])
    q = np.concatenate([s.q_AB for s in aem.segments])
    if inertial_b:
        q = rotations.quat_conjugate(q)  # q_AB = q_SI -> q_IS
    notes = [f"CCSDS AEM {aem.version}: {len(aem.segments)} segment(s), {t.size} attitudes, "
             f"{sensor_frame} relative to {inertial}"]
    if inertial != "GCRF":
        q = rotations.quat_multiply(rotations.dcm_to_quat(inertial_to_gcrs_mat(inertial, t)), q)
        notes.append(f"converted from {inertial} to GCRF (IAU 2006/2000A)")
    types = sorted({s.metadata["ATTITUDE_TYPE"].upper() for s in aem.segments})
    if types != ["QUATERNION"]:
        notes.append(f"ATTITUDE_TYPE {', '.join(types)}: rates/derivatives are not stored")
    order = np.argsort(t, kind="stable")
    table = pa.table({"time": _times(t[order]), **{f"q{i}": q[order, i] for i in range(4)}})
    return Decoded(table=table, time_scale="tai", quaternion_direction="sensor_to_inertial", sensor=None,
                   notes=tuple(notes))


def decode_oem(body: bytes, stream: str) -> Decoded:
    oem = parse_oem(body)
    ts: list[np.ndarray] = []
    rs: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    notes = [f"CCSDS OEM {oem.version}: {len(oem.segments)} segment(s)"]
    for seg in oem.segments:
        if seg.metadata["CENTER_NAME"].strip().upper() != "EARTH":
            raise ValueError(f"CENTER_NAME must be EARTH for GNSS states, got {seg.metadata['CENTER_NAME']!r}")
        r, v = seg.position_m, seg.velocity_m_s
        if not is_earth_fixed(seg.ref_frame):
            inertial = _inertial(seg.ref_frame)
            if inertial is None:
                raise ValueError(f"REF_FRAME {seg.ref_frame!r} is neither an ITRF nor a supported inertial frame "
                                 "(GCRF, ICRF, EME2000, J2000, MOD, TOD, TEME)")
            r, v = inertial_to_itrs_state(inertial, r, v, seg.time_tai_ns)
            notes.append(f"segment {len(ts) + 1}: {seg.ref_frame} converted to ITRF with zero EOP "
                         "(UT1-UTC = 0, no polar motion)")
        ts.append(seg.time_tai_ns)
        rs.append(r)
        vs.append(v)
    t, r, v = np.concatenate(ts), np.concatenate(rs), np.concatenate(vs)
    order = np.argsort(t, kind="stable")
    cols = {"time": _times(t[order])}
    cols.update({c: r[order, i] for i, c in enumerate(("x", "y", "z"))})
    cols.update({c: v[order, i] for i, c in enumerate(("vx", "vy", "vz"))})
    return Decoded(table=pa.table(cols), time_scale="tai", sensor=None, notes=tuple(notes))


DECODERS = {
    "ccsds-aem": Decoder("ccsds-aem", ("star_tracker",), decode_aem,
                         "CCSDS Attitude Ephemeris Message, KVN, ADM 1.0 or 2.0 (quaternions or Euler angles; "
                         "one frame inertial, converted to GCRF)", media_types=("text/plain",)),
    "ccsds-oem": Decoder("ccsds-oem", ("gnss",), decode_oem,
                         "CCSDS Orbit Ephemeris Message, KVN, ODM 2.0 or 3.0 (ITRF, or inertial frames converted "
                         "to ITRF with zero EOP)", media_types=("text/plain",)),
}
