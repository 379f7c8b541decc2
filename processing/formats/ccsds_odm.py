"""CCSDS Orbit Ephemeris Message (OEM), KVN, versions 2.0 and 3.0: read and write.

Standard: CCSDS 502.0-B-2 (ODM 2.0, 2009) and 502.0-B-3 (ODM 3.0, April 2023), §5 (OEM) and §7
(KVN). Structure: header (CCSDS_OEM_VERS, COMMENT, CLASSIFICATION [3.0], CREATION_DATE,
ORIGINATOR, MESSAGE_ID [3.0]); then one or more segments: META_START ... META_STOP (OBJECT_NAME,
OBJECT_ID, CENTER_NAME, REF_FRAME, REF_FRAME_EPOCH, TIME_SYSTEM, START_TIME, USEABLE_START_TIME,
USEABLE_STOP_TIME, STOP_TIME, INTERPOLATION, INTERPOLATION_DEGREE), data lines
``EPOCH X Y Z X_DOT Y_DOT Z_DOT [X_DDOT Y_DDOT Z_DDOT]`` in km, km/s, km/s**2 (comments allowed
before the first), and an optional COVARIANCE_START ... COVARIANCE_STOP block (EPOCH,
COV_REF_FRAME, then the lower triangle of a 6x6 matrix row by row, km**2, km**2/s, km**2/s**2).

Values are kept as the file gives them (km, km/s), so that :func:`parse_oem` of :func:`write_oem`
returns the same numbers bit for bit; ``position_m``/``velocity_m_s`` give SI. Covariances are read
(lower triangle expanded to the symmetric matrix) and written back.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

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

HEADER_KEYS = ("CCSDS_OEM_VERS", "CLASSIFICATION", "CREATION_DATE", "ORIGINATOR", "MESSAGE_ID")
METADATA_KEYS = ("OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "REF_FRAME", "REF_FRAME_EPOCH", "TIME_SYSTEM",
                 "START_TIME", "USEABLE_START_TIME", "USEABLE_STOP_TIME", "STOP_TIME", "INTERPOLATION",
                 "INTERPOLATION_DEGREE")
MANDATORY_METADATA = ("OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "REF_FRAME", "TIME_SYSTEM", "START_TIME",
                      "STOP_TIME")
EARTH_FIXED_FRAMES = ("ITRF", "ITRF93", "ITRF97", "ITRF2000", "ITRF2005", "ITRF2008", "ITRF2014", "ITRF2020",
                      "ITRF-93", "ITRF-97", "ITRF1993", "ITRF1997", "ITRS", "EFG", "GRC")
"""REF_FRAME values taken as the ITRS (realisations differ by cm, below GNSS noise)."""


class OemError(KvnError):
    """An OEM that cannot be read; the message names the line and keyword."""


@dataclass(frozen=True)
class OemCovariance:
    """One covariance block entry: epoch, frame (None: the segment's REF_FRAME), matrix (6, 6) in
    km**2, km**2/s, km**2/s**2 as in the file (symmetric, from the lower triangle)."""

    time_tai_ns: int
    ref_frame: str | None
    matrix: NDArray
    comments: tuple[str, ...] = ()


@dataclass(frozen=True)
class OemSegment:
    """One segment: metadata (keyword -> value, file order), comments, time_tai_ns (N,),
    position_km (N, 3), velocity_km_s (N, 3), acceleration_km_s2 (N, 3) or None, covariances."""

    metadata: dict[str, str]
    time_tai_ns: NDArray
    position_km: NDArray
    velocity_km_s: NDArray
    acceleration_km_s2: NDArray | None = None
    covariances: tuple[OemCovariance, ...] = ()
    comments: tuple[str, ...] = ()
    data_comments: tuple[str, ...] = ()

    @property
    def ref_frame(self) -> str:
        return self.metadata["REF_FRAME"]

    @property
    def time_system(self) -> str:
        return self.metadata["TIME_SYSTEM"]

    @property
    def position_m(self) -> NDArray:
        return self.position_km * 1000.0

    @property
    def velocity_m_s(self) -> NDArray:
        return self.velocity_km_s * 1000.0


@dataclass(frozen=True)
class Oem:
    """A parsed OEM: version ("2.0", "3.0"), header (keyword -> value), segments, header comments."""

    version: str
    header: dict[str, str]
    segments: tuple[OemSegment, ...]
    comments: tuple[str, ...] = field(default=())


def _covariances(lines: list[Line], i: int, scale: str, where: str) -> tuple[list[OemCovariance], int]:
    """Parse a COVARIANCE_START..STOP block starting after the START marker at lines[i]."""
    out: list[OemCovariance] = []
    epoch: int | None = None
    frame: str | None = None
    rows: list[list[float]] = []
    comments: list[str] = []

    def flush(at: Line) -> None:
        nonlocal epoch, frame, rows, comments
        if epoch is None:
            return
        if len(rows) != 6 or any(len(r) != k + 1 for k, r in enumerate(rows)):
            raise OemError(f"line {at.number}: a covariance needs the 21 lower-triangle values on 6 rows "
                           f"of 1..6 numbers, got rows of {[len(r) for r in rows]}")
        m = np.zeros((6, 6))
        for k, r in enumerate(rows):
            m[k, :k + 1] = r
        m = m + np.tril(m, -1).T
        out.append(OemCovariance(epoch, frame, m, tuple(comments)))
        epoch, frame, rows, comments = None, None, [], []

    while i < len(lines) and lines[i].key != "COVARIANCE_STOP":
        ln = lines[i]
        if ln.kind == "comment":
            comments.append(ln.value)
        elif ln.kind == "kv" and ln.key == "EPOCH":
            flush(ln)
            epoch = int(parse_epochs([ln.value], scale, where)[0])
        elif ln.kind == "kv" and ln.key == "COV_REF_FRAME":
            frame = ln.value
        elif ln.kind == "data" and epoch is not None:
            rows.append(parse_floats(ln.value.split(), ln, "covariance values"))
        else:
            raise OemError(f"line {ln.number}: unexpected {ln.text[:60]!r} in a covariance block")
        i += 1
    if i >= len(lines):
        raise OemError(f"{where}: COVARIANCE_START without COVARIANCE_STOP")
    flush(lines[i])
    return out, i + 1


def parse_oem(text: str | bytes) -> Oem:
    """Read an OEM (KVN, 2.0 or 3.0) into :class:`Oem`; OemError (a ValueError) names what is wrong."""
    lines = list(tokenize(text))
    if not lines or lines[0].key != "CCSDS_OEM_VERS":
        first = lines[0].text[:60] if lines else "an empty file"
        raise OemError(f"an OEM starts with CCSDS_OEM_VERS = 2.0 or 3.0, got {first!r}")
    version = lines[0].value
    if version not in ("1.0", "2.0", "3.0"):
        raise OemError(f"line {lines[0].number}: CCSDS_OEM_VERS {version!r} is not supported (2.0, 3.0)")
    head, i = read_block(lines, 1, "META_START", HEADER_KEYS, "the OEM header", OemError, unique=False)
    header = {"CCSDS_OEM_VERS": version, **head.values}
    header_comments = head.comments
    for key in ("CREATION_DATE", "ORIGINATOR"):
        if key not in header:
            raise OemError(f"the OEM header lacks the mandatory {key}")
    segments: list[OemSegment] = []
    while i < len(lines):
        if lines[i].key != "META_START":
            raise OemError(f"line {lines[i].number}: expected META_START, got {lines[i].text[:60]!r}")
        start_line = lines[i].number
        where = f"segment at line {start_line}"
        block, i = read_block(lines, i + 1, "META_STOP", METADATA_KEYS, "the OEM metadata block", OemError,
                              unique=True)
        meta, comments = block.values, block.comments
        if i >= len(lines):
            raise OemError(f"{where}: no META_STOP")
        i += 1
        missing = [k for k in MANDATORY_METADATA if k not in meta]
        if missing:
            raise OemError(f"{where}: mandatory keyword(s) missing: {', '.join(missing)}")
        scale = time_scale(meta["TIME_SYSTEM"], where)
        data: list[Line] = []
        data_comments: list[str] = []
        while i < len(lines) and lines[i].kind in ("data", "comment"):
            if lines[i].kind == "comment":
                if data:
                    raise OemError(f"line {lines[i].number}: comments are allowed only before the first data line")
                data_comments.append(lines[i].value)
            else:
                data.append(lines[i])
            i += 1
        if not data:
            raise OemError(f"{where}: no ephemeris data lines")
        fields = [d.value.split() for d in data]
        widths = {len(f) for f in fields}
        if not widths <= {7, 10} or len(widths) != 1:
            bad = next(d for d, f in zip(data, fields, strict=True)
                       if len(f) not in (7, 10) or len(f) != len(fields[0]))
            raise OemError(f"line {bad.number}: ephemeris lines need an epoch and 6 (or 9, with accelerations) "
                           f"numbers, all lines alike; got {len(bad.value.split())} fields")
        values = np.array([parse_floats(f[1:], d, "state components") for d, f in zip(data, fields, strict=True)])
        if not np.all(np.isfinite(values)):
            raise OemError(f"{where}: non-finite state values")
        t = parse_epochs([f[0] for f in fields], scale, where)
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise OemError(f"line {data[k].number}: epochs must increase")
        covs: list[OemCovariance] = []
        if i < len(lines) and lines[i].key == "COVARIANCE_START":
            covs, i = _covariances(lines, i + 1, scale, where)
        segments.append(OemSegment(
            metadata=meta, time_tai_ns=t, position_km=values[:, 0:3], velocity_km_s=values[:, 3:6],
            acceleration_km_s2=values[:, 6:9] if values.shape[1] == 9 else None, covariances=tuple(covs),
            comments=tuple(comments), data_comments=tuple(data_comments)))
    if not segments:
        raise OemError("the OEM has no segment")
    return Oem(version=version, header=header, segments=tuple(segments), comments=tuple(header_comments))


def oem_segment(
    time_tai_ns: ArrayLike, position_m: ArrayLike, velocity_m_s: ArrayLike, *, object_name: str, object_id: str,
    ref_frame: str = "ITRF", center_name: str = "EARTH", time_system: str = "UTC",
    comments: tuple[str, ...] = (), interpolation: tuple[str, int] | None = ("LAGRANGE", 7),
) -> OemSegment:
    """An OEM segment from SI states (N, 3) at tai_ns (N,), stored in km and km/s as written."""
    t = np.asarray(time_tai_ns, dtype=np.int64)
    r = np.asarray(position_m, dtype=np.float64)
    v = np.asarray(velocity_m_s, dtype=np.float64)
    if t.ndim != 1 or t.size == 0 or r.shape != (t.size, 3) or v.shape != (t.size, 3):
        raise OemError(f"expected times (N,), positions and velocities (N, 3), N > 0; got {t.shape}, {r.shape}, "
                       f"{v.shape}")
    scale = time_scale(time_system, "OEM writer")
    first, last = format_epochs(t[[0, -1]], scale)
    meta = {"OBJECT_NAME": object_name, "OBJECT_ID": object_id, "CENTER_NAME": center_name,
            "REF_FRAME": ref_frame, "TIME_SYSTEM": time_system.upper(), "START_TIME": first, "STOP_TIME": last}
    if interpolation is not None:
        meta["INTERPOLATION"], meta["INTERPOLATION_DEGREE"] = interpolation[0], str(interpolation[1])
    return OemSegment(metadata=meta, time_tai_ns=t, position_km=r / 1000.0, velocity_km_s=v / 1000.0,
                      comments=tuple(comments))


def write_oem(segments: list[OemSegment] | tuple[OemSegment, ...], *, originator: str, version: str = "3.0",
              creation_date: dt.datetime | None = None, message_id: str | None = None,
              comments: tuple[str, ...] = ()) -> str:
    """KVN text of an OEM (version 2.0 or 3.0) with the given segments, numbers in shortest
    round-trip form and epochs exact to the nanosecond."""
    if version not in ("2.0", "3.0"):
        raise OemError(f"version must be 2.0 or 3.0, got {version!r}")
    created = (creation_date or dt.datetime.now(dt.UTC)).strftime("%Y-%m-%dT%H:%M:%S")
    out = [f"CCSDS_OEM_VERS = {version}"]
    out += [f"COMMENT {c}" for c in comments]
    out += [f"CREATION_DATE = {created}", f"ORIGINATOR = {originator}"]
    if message_id and version == "3.0":
        out.append(f"MESSAGE_ID = {message_id}")
    for seg in segments:
        scale = time_scale(seg.time_system, "OEM writer")
        out += ["", "META_START"]
        out += [f"COMMENT {c}" for c in seg.comments]
        out += [f"{k} = {v}" for k, v in seg.metadata.items()]
        out += ["META_STOP", ""]
        out += [f"COMMENT {c}" for c in seg.data_comments]
        cols = [seg.position_km, seg.velocity_km_s] + ([seg.acceleration_km_s2] if seg.acceleration_km_s2 is not None
                                                         else [])
        values = np.concatenate(cols, axis=1)
        epochs = format_epochs(seg.time_tai_ns, scale)
        out += [f"{e} " + " ".join(format_float(x) for x in row) for e, row in zip(epochs, values, strict=True)]
        if seg.covariances:
            out += ["", "COVARIANCE_START"]
            for cov in seg.covariances:
                out += [f"COMMENT {c}" for c in cov.comments]
                out.append(f"EPOCH = {format_epochs(np.array([cov.time_tai_ns]), scale)[0]}")
                if cov.ref_frame:
                    out.append(f"COV_REF_FRAME = {cov.ref_frame}")
                out += [" ".join(format_float(x) for x in cov.matrix[k, :k + 1]) for k in range(6)]
            out.append("COVARIANCE_STOP")
    return "\n".join(out) + "\n"


def is_earth_fixed(ref_frame: str) -> bool:
    """True for REF_FRAME names of the ITRS (any ITRF realisation)."""
    name = ref_frame.strip().upper()
    return name in EARTH_FIXED_FRAMES or name.startswith("ITRF")
