"""Upload format ``gracefo-l1b``: GRACE-FO Level-1B ASCII products (processing/formats/gracefo_l1b.py).

SCA1B -> star_tracker (q_IS of the Science Reference Frame, scalar first), GNV1B -> gnss (ITRF; an
inertial GNV1B is converted with zero EOP), IMU1B -> gyro (rates by central differences of the
filtered angles) or gyro_increments (angle differences), MAG1B -> magnetometer (nT). Times are GPS
time; they are passed on as TAI ISO strings, exact to the nanosecond. The product must match the
stream of the upload route (a 422 says which stream a product feeds).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from app.ingest.formats import Decoded, Decoder
from processing.formats import gracefo_l1b as l1b
from processing.frames.earth_orientation import inertial_to_itrs_state
from processing.time import timescales

FEEDS = {"SCA1B": ("star_tracker",), "GNV1B": ("gnss",), "IMU1B": ("gyro", "gyro_increments"),
         "MAG1B": ("magnetometer",)}


def _times(t: np.ndarray) -> pa.Array:
    return pa.array(timescales.tai_ns_to_iso(t, "tai").tolist(), pa.string())


def decode(body: bytes, stream: str) -> Decoded:
    f = l1b.parse_l1b(body)
    if stream not in FEEDS[f.product]:
        raise ValueError(f"a {f.product} file feeds the {' or '.join(FEEDS[f.product])} stream, not {stream}")
    notes = [f"GRACE-FO {f.satellite} {f.product}, {f.n_rows} rows, GPS time"]
    if f.product == "SCA1B":
        t, q = l1b.sca_quaternions(f)
        notes.append("quaternion of the Science Reference Frame (SRF -> inertial); configure the star tracker "
                     "with q_BS = identity to take the SRF as the body frame")
        cols = {"time": _times(t), **{f"q{i}": q[:, i] for i in range(4)}}
    elif f.product == "GNV1B":
        t, r, v, frame = l1b.gnv_states(f)
        if frame == "I":
            r, v = inertial_to_itrs_state("GCRF", r, v, t)
            notes.append("coord_ref I: converted from the inertial frame (taken as GCRF) to ITRF with zero EOP")
        cols = {"time": _times(t), **{c: r[:, i] for i, c in enumerate(("x", "y", "z"))},
                **{c: v[:, i] for i, c in enumerate(("vx", "vy", "vz"))}}
    elif f.product == "IMU1B":
        t, angles, extra = l1b.imu_angles(f)
        notes += list(extra)
        notes.append("IMU1B axes are the gyro axes of the instrument (not the SRF): configure gyro.q_BG")
        if stream == "gyro":
            tr, w = l1b.imu_rates(t, angles)
            notes.append("rates by central differences of the filtered angles")
            cols = {"time": _times(tr), **{c: w[:, i] for i, c in enumerate(("wx", "wy", "wz"))}}
        else:
            ti, inc, dt = l1b.imu_increments(t, angles)
            cols = {"time": _times(ti), **{c: inc[:, i] for i, c in enumerate(("dax", "day", "daz"))},
                    "interval_s": dt}
    else:
        t, b, extra = l1b.mag_field_nt(f)
        notes += list(extra)
        notes.append("field in the SRF, microtesla converted to nT (raw, uncalibrated values)")
        cols = {"time": _times(t), **{c: b[:, i] for i, c in enumerate(("bx", "by", "bz"))}}
    return Decoded(table=pa.table(cols), time_scale="tai", quaternion_direction="sensor_to_inertial", sensor=None,
                   notes=tuple(notes))


DECODERS = {
    "gracefo-l1b": Decoder(
        "gracefo-l1b", ("star_tracker", "gnss", "gyro", "gyro_increments", "magnetometer"), decode,
        "GRACE-FO Level-1B ASCII (release 04): SCA1B -> star_tracker, GNV1B -> gnss, IMU1B -> gyro or "
        "gyro_increments, MAG1B -> magnetometer", media_types=("text/plain",)),
}
