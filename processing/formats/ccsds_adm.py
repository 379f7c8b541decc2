"""CCSDS Attitude Ephemeris Message (AEM), KVN, versions 1.0 and 2.0: read and write.

Standard: CCSDS 504.0-B-2 (ADM 2.0, January 2024) §4 and Annex F; 504.0-B-1 (ADM 1.0, 2008) for
the 1.0 keywords. Quaternion convention (ADM 2.0 Annex F2): the quaternion 'from frame A to frame
B' is that of the rotation taking the basis vectors of A into those of B, Q = (e sin(phi/2),
cos(phi/2)) with the frame transformation X_B = M_BA X_A. With our conventions (DESIGN.md) that
is q_AB (B coordinates -> A coordinates) scalar first: dcm_AB = M_BA^T. Worked example (Annex
F2.2): B = A turned +90 deg about Z, Q = (0, 0, 0.7071, 0.7071), X_A = (1, 0, 0) has X_B = (0, -1, 0).

Version differences handled on reading:
- 2.0: data lines are EPOCH Q1 Q2 Q3 QC (scalar last, always from A to B).
- 1.0: QUATERNION_TYPE = FIRST | LAST says where QC is; ATTITUDE_DIR = A2B | B2A the direction
  (B2A: the quaternion from B to A, i.e. q_BA; conjugated here to give q_AB);
  QUATERNION/RATE and EULER_ANGLE/RATE are 1.0's names of the */ANGVEL types; EULER_ROT_SEQ is
  digits (321) in 1.0, letters (ZYX) in 2.0.
Attitude types read: QUATERNION, QUATERNION/DERIVATIVE, QUATERNION/ANGVEL (QUATERNION/RATE),
EULER_ANGLE, EULER_ANGLE/DERIVATIVE, EULER_ANGLE/ANGVEL (EULER_ANGLE/RATE); Euler angles (deg) are
turned into q_AB by Annex F3 (three intrinsic rotations taking A into B, q_AB = q_a1 o q_a2 o q_a3).
SPIN types are rejected. The columns after the attitude (rates, derivatives) are kept as ``extra``.

Written: version 2.0, ATTITUDE_TYPE = QUATERNION, one segment per block given, epochs exact to the
nanosecond and numbers in shortest round-trip form, so that :func:`parse_aem` of :func:`write_aem`
gives back the same message (tested).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.formats.ccsds_kvn import (
    KvnError,
    Line,
    format_epochs,
    format_float,
    parse_epochs,
    parse_floats,
    read_block,
    time_scale,
    tokenize,
)

HEADER_KEYS = ("CCSDS_AEM_VERS", "CLASSIFICATION", "CREATION_DATE", "ORIGINATOR", "MESSAGE_ID")
METADATA_KEYS = (
    "OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "REF_FRAME_A", "REF_FRAME_B", "ATTITUDE_DIR", "TIME_SYSTEM",
    "START_TIME", "USEABLE_START_TIME", "USEABLE_STOP_TIME", "STOP_TIME", "ATTITUDE_TYPE", "QUATERNION_TYPE",
    "EULER_ROT_SEQ", "RATE_FRAME", "ANGVEL_FRAME", "INTERPOLATION_METHOD", "INTERPOLATION_DEGREE",
)
MANDATORY_METADATA = ("OBJECT_NAME", "OBJECT_ID", "REF_FRAME_A", "REF_FRAME_B", "TIME_SYSTEM", "START_TIME",
                      "STOP_TIME", "ATTITUDE_TYPE")
ATTITUDE_TYPES = {
    # type: (angle/quaternion fields, extra fields)
    "QUATERNION": (4, 0), "QUATERNION/DERIVATIVE": (4, 4), "QUATERNION/ANGVEL": (4, 3),
    "QUATERNION/RATE": (4, 3), "EULER_ANGLE": (3, 0), "EULER_ANGLE/DERIVATIVE": (3, 3),
    "EULER_ANGLE/ANGVEL": (3, 3), "EULER_ANGLE/RATE": (3, 3),
}
NORM_TOLERANCE = 1e-2
"""Quaternions are kept as written (not renormalised, so messages read back bit for bit); a norm
further than this from 1 is an error (the ingest then checks its own, tighter tolerance)."""
_AXES = {"X": 0, "Y": 1, "Z": 2, "1": 0, "2": 1, "3": 2}


class AemError(KvnError):
    """An AEM that cannot be read; the message names the line and keyword."""


@dataclass(frozen=True)
class AemSegment:
    """One metadata block and its data: ``metadata`` (keyword -> value, file order), comments,
    time_tai_ns (N,), q_AB (N, 4) scalar first from REF_FRAME_A to REF_FRAME_B in our convention
    (q_AB maps B coordinates to A coordinates), ``extra`` (N, k) the remaining data columns as given
    (rates, derivatives; k = 0 for QUATERNION)."""

    metadata: dict[str, str]
    time_tai_ns: NDArray
    q_AB: NDArray
    extra: NDArray
    comments: tuple[str, ...] = ()
    data_comments: tuple[str, ...] = ()

    @property
    def ref_frame_a(self) -> str:
        return self.metadata["REF_FRAME_A"]

    @property
    def ref_frame_b(self) -> str:
        return self.metadata["REF_FRAME_B"]

    @property
    def time_system(self) -> str:
        return self.metadata["TIME_SYSTEM"]


@dataclass(frozen=True)
class Aem:
    """A parsed AEM: version ("1.0", "2.0"), header (keyword -> value), header comments, segments."""

    version: str
    header: dict[str, str]
    segments: tuple[AemSegment, ...]
    comments: tuple[str, ...] = field(default=())


def quat_from_euler(angles_deg: ArrayLike, sequence: str) -> NDArray:
    """q_AB (N, 4) from ADM Euler angles 'from A to B' (Annex F3): rotations about a1, a2, a3 of the
    current frame taking A into B, so q_AB = q_a1(theta1) o q_a2(theta2) o q_a3(theta3).

    angles_deg (N, 3) [deg]; sequence "XYZ"-style letters (2.0) or "123"-style digits (1.0).
    """
    seq = sequence.strip().upper()
    if len(seq) != 3 or any(c not in _AXES for c in seq):
        raise AemError(f"EULER_ROT_SEQ must be three axes like ZXZ or 313, got {sequence!r}")
    a = np.radians(np.asarray(angles_deg, dtype=np.float64))
    q = np.zeros(a.shape[:-1] + (4,))
    q[..., 0] = 1.0
    for k, c in enumerate(seq):
        axis = np.zeros(3)
        axis[_AXES[c]] = 1.0
        q = rotations.quat_multiply(q, rotations.quat_from_axis_angle(axis, a[..., k]))
    return q


def _version(lines: list[Line]) -> str:
    if not lines or lines[0].kind != "kv" or lines[0].key != "CCSDS_AEM_VERS":
        first = lines[0].text[:60] if lines else "an empty file"
        raise AemError(f"an AEM starts with CCSDS_AEM_VERS = 1.0 or 2.0, got {first!r}")
    version = lines[0].value
    if version not in ("1.0", "2.0"):
        raise AemError(f"line {lines[0].number}: CCSDS_AEM_VERS {version!r} is not supported (1.0, 2.0)")
    return version


def _segment(version: str, meta: dict[str, str], meta_lines: dict[str, int], comments: list[str],
             data: list[Line], data_comments: list[str], start_line: int) -> AemSegment:
    where = f"metadata block at line {start_line}"
    missing = [k for k in MANDATORY_METADATA if k not in meta]
    if missing:
        raise AemError(f"{where}: mandatory keyword(s) missing: {', '.join(missing)}")
    att_type = meta["ATTITUDE_TYPE"].upper()
    if att_type not in ATTITUDE_TYPES:
        raise AemError(f"line {meta_lines['ATTITUDE_TYPE']}: ATTITUDE_TYPE {meta['ATTITUDE_TYPE']!r} is not "
                       f"supported; expected one of {', '.join(ATTITUDE_TYPES)}")
    n_att, n_extra = ATTITUDE_TYPES[att_type]
    direction = meta.get("ATTITUDE_DIR", "A2B").upper()
    if direction not in ("A2B", "B2A"):
        raise AemError(f"line {meta_lines['ATTITUDE_DIR']}: ATTITUDE_DIR must be A2B or B2A, got {direction!r}")
    if version == "1.0" and "ATTITUDE_DIR" not in meta:
        raise AemError(f"{where}: AEM 1.0 needs ATTITUDE_DIR (A2B or B2A)")
    scalar = meta.get("QUATERNION_TYPE", "LAST" if version == "2.0" else "").upper()
    if n_att == 4 and scalar not in ("FIRST", "LAST"):
        raise AemError(f"{where}: AEM 1.0 quaternions need QUATERNION_TYPE = FIRST or LAST")
    if n_att == 3 and "EULER_ROT_SEQ" not in meta:
        raise AemError(f"{where}: Euler angles need EULER_ROT_SEQ")
    if not data:
        raise AemError(f"{where}: no data lines between DATA_START and DATA_STOP")
    fields = [d.value.split() for d in data]
    width = 1 + n_att + n_extra
    for d, f in zip(data, fields, strict=True):
        if len(f) != width:
            raise AemError(f"line {d.number}: ATTITUDE_TYPE {att_type} needs {width} fields (epoch and "
                           f"{width - 1} numbers), got {len(f)}")
    values = np.array([parse_floats(f[1:], d, "attitude data") for d, f in zip(data, fields, strict=True)])
    if not np.all(np.isfinite(values)):
        bad = data[int(np.argmax(~np.all(np.isfinite(values), axis=1)))]
        raise AemError(f"line {bad.number}: non-finite value")
    scale = time_scale(meta["TIME_SYSTEM"], where)
    t = parse_epochs([f[0] for f in fields], scale, where)
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise AemError(f"line {data[k].number}: epochs must increase (ADM 4.2.4.8.1)")
    att = values[:, :n_att]
    if n_att == 4:
        q = att if scalar == "FIRST" else att[:, [3, 0, 1, 2]]
        norm = np.linalg.norm(q, axis=1)
        bad = np.abs(norm - 1.0) > NORM_TOLERANCE
        if np.any(bad):
            k = int(np.argmax(bad))
            raise AemError(f"line {data[k].number}: quaternion norm {norm[k]:.6g} differs from 1 by more than "
                           f"{NORM_TOLERANCE:g}")
    else:
        q = quat_from_euler(att, meta["EULER_ROT_SEQ"])
    if direction == "B2A":
        q = rotations.quat_conjugate(q)
    return AemSegment(metadata=dict(meta), time_tai_ns=t, q_AB=q, extra=values[:, n_att:],
                      comments=tuple(comments), data_comments=tuple(data_comments))


def parse_aem(text: str | bytes) -> Aem:
    """Read an AEM (KVN, 1.0 or 2.0) into :class:`Aem`; AemError (a ValueError) names what is wrong."""
    lines = list(tokenize(text))
    version = _version(lines)
    head, i = read_block(lines, 1, "META_START", HEADER_KEYS, "the AEM header", AemError, unique=False)
    header: dict[str, str] = {"CCSDS_AEM_VERS": version, **head.values}
    header_comments = head.comments
    segments: list[AemSegment] = []
    for key in ("CREATION_DATE", "ORIGINATOR"):
        if key not in header:
            raise AemError(f"the AEM header lacks the mandatory {key}")
    while i < len(lines):
        if lines[i].key != "META_START":
            raise AemError(f"line {lines[i].number}: expected META_START, got {lines[i].text[:60]!r}")
        start_line = lines[i].number
        block, i = read_block(lines, i + 1, "META_STOP", METADATA_KEYS, "the AEM metadata block", AemError,
                              unique=True)
        meta, meta_lines, comments = block.values, block.line_of, block.comments
        if i >= len(lines):
            raise AemError(f"metadata block at line {start_line}: no META_STOP")
        i += 1
        if i >= len(lines) or lines[i].key != "DATA_START":
            got = lines[i].text[:60] if i < len(lines) else "the end of the file"
            raise AemError(f"after META_STOP expected DATA_START, got {got!r}")
        i += 1
        data: list[Line] = []
        data_comments: list[str] = []
        while i < len(lines) and lines[i].key != "DATA_STOP":
            ln = lines[i]
            if ln.kind == "comment" and not data:
                data_comments.append(ln.value)
            elif ln.kind == "data":
                data.append(ln)
            else:
                raise AemError(f"line {ln.number}: unexpected {ln.text[:60]!r} in AEM data")
            i += 1
        if i >= len(lines):
            raise AemError(f"data block after line {start_line}: no DATA_STOP")
        i += 1
        segments.append(_segment(version, meta, meta_lines, comments, data, data_comments, start_line))
    if not segments:
        raise AemError("the AEM has no metadata/data block")
    return Aem(version=version, header=header, segments=tuple(segments), comments=tuple(header_comments))


def aem_segment(
    time_tai_ns: ArrayLike, q_AB: ArrayLike, *, object_name: str, object_id: str, ref_frame_a: str,
    ref_frame_b: str, time_system: str = "UTC", center_name: str | None = "EARTH",
    comments: tuple[str, ...] = (), interpolation: tuple[str, int] | None = None,
) -> AemSegment:
    """Build an AEM 2.0 QUATERNION segment from our q_AB (N, 4) scalar first (unit to 1e-9; signs made
    canonical, values otherwise kept bit for bit) at tai_ns (N,)."""
    t = np.asarray(time_tai_ns, dtype=np.int64)
    q = np.asarray(q_AB, dtype=np.float64)
    if t.ndim != 1 or q.shape != (t.size, 4) or t.size == 0:
        raise AemError(f"expected times (N,) and quaternions (N, 4) with N > 0, got {t.shape} and {q.shape}")
    norm = np.linalg.norm(q, axis=1)
    if np.any(np.abs(norm - 1.0) > 1e-9):
        raise AemError(f"quaternions must be unit (to 1e-9), got norms from {norm.min():.12g} to {norm.max():.12g}")
    q = rotations.quat_canonical(q)  # written as given otherwise, so the file holds the caller's numbers
    scale = time_scale(time_system, "AEM writer")
    first, last = format_epochs(t[[0, -1]], scale)
    meta = {"OBJECT_NAME": object_name, "OBJECT_ID": object_id}
    if center_name:
        meta["CENTER_NAME"] = center_name
    meta.update({"REF_FRAME_A": ref_frame_a, "REF_FRAME_B": ref_frame_b, "TIME_SYSTEM": time_system.upper(),
                 "START_TIME": first, "STOP_TIME": last, "ATTITUDE_TYPE": "QUATERNION"})
    if interpolation is not None:
        meta["INTERPOLATION_METHOD"], meta["INTERPOLATION_DEGREE"] = interpolation[0], str(interpolation[1])
    return AemSegment(metadata=meta, time_tai_ns=t, q_AB=q, extra=np.zeros((t.size, 0)), comments=tuple(comments))


def write_aem(segments: list[AemSegment] | tuple[AemSegment, ...], *, originator: str,
              creation_date: dt.datetime | None = None, message_id: str | None = None,
              comments: tuple[str, ...] = ()) -> str:
    """KVN text of an AEM 2.0 with the given QUATERNION segments (Q1 Q2 Q3 QC, from A to B)."""
    created = (creation_date or dt.datetime.now(dt.UTC)).strftime("%Y-%m-%dT%H:%M:%S")
    out = ["CCSDS_AEM_VERS = 2.0"]
    out += [f"COMMENT {c}" for c in comments]
    out += [f"CREATION_DATE = {created}", f"ORIGINATOR = {originator}"]
    if message_id:
        out.append(f"MESSAGE_ID = {message_id}")
    for seg in segments:
        if seg.metadata.get("ATTITUDE_TYPE", "QUATERNION") != "QUATERNION":
            raise AemError("the writer handles ATTITUDE_TYPE = QUATERNION segments only")
        out += ["", "META_START"]
        out += [f"COMMENT {c}" for c in seg.comments]
        out += [f"{k} = {v}" for k, v in seg.metadata.items() if k not in ("ATTITUDE_DIR", "QUATERNION_TYPE")]
        out += ["META_STOP", "", "DATA_START"]
        out += [f"COMMENT {c}" for c in seg.data_comments]
        epochs = format_epochs(seg.time_tai_ns, time_scale(seg.time_system, "AEM writer"))
        q = rotations.quat_to_ccsds(seg.q_AB)
        out += [f"{e} " + " ".join(format_float(x) for x in row) for e, row in zip(epochs, q, strict=True)]
        out.append("DATA_STOP")
    return "\n".join(out) + "\n"
