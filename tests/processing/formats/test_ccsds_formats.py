"""CCSDS AEM (ADM 1.0/2.0) and OEM (ODM 2.0/3.0) KVN readers and writers.

Authorities: CCSDS 504.0-B-2 (ADM 2.0) Annex F2.2 worked example and Figure G-4 (AEM example);
CCSDS 502.0-B-3 (ODM 3.0) OEM example (tests/data/oem_mgs_example.txt). Cross-checks with two
independent parsers from PyPI when installed: ``oem`` (python-oem) and ``ccsds-ndm-py``.
"""

import datetime as dt

import numpy as np
import pytest

from processing.attitude import rotations
from processing.formats.ccsds_adm import AemError, aem_segment, parse_aem, quat_from_euler, write_aem
from processing.formats.ccsds_kvn import KvnError, format_float, parse_epochs
from processing.formats.ccsds_odm import OemError, is_earth_fixed, oem_segment, parse_oem, write_oem
from processing.time import timescales
from tests.real_data import REFERENCE

DATA = REFERENCE
CREATED = dt.datetime(2023, 6, 1, 12, 0, 0, tzinfo=dt.UTC)

AEM_G4 = """CCSDS_AEM_VERS = 2.0
CREATION_DATE = 2002-11-04T17:22:31
ORIGINATOR    = NASA/JPL
MESSAGE_ID    = A701523

META_START
COMMENT This file was produced by M.R. Somebody, MSOO NAV/JPL.
COMMENT It is to be used for attitude reconstruction only. The relative accuracy of these
COMMENT attitudes is 0.1 degrees per axis.
OBJECT_NAME       = MARS_GLOBAL_SURVEYOR
OBJECT_ID         = 1996-062A
CENTER_NAME       = MARS BARYCENTER
REF_FRAME_A         = EME2000
REF_FRAME_B         = SC_BODY_1
TIME_SYSTEM       = UTC
START_TIME        = 1996-11-28T21:29:07.2555
USEABLE_START_TIME = 1996-11-28T22:08:02.5555
USEABLE_STOP_TIME  = 1996-11-30T01:18:02.5555
STOP_TIME         = 1996-11-30T01:28:02.5555
ATTITUDE_TYPE     = QUATERNION
INTERPOLATION_METHOD = HERMITE
INTERPOLATION_DEGREE = 7
META_STOP

DATA_START
1996-11-28T21:29:07.2555 0.56748 0.03146 0.45689 0.68427
1996-11-28T22:08:03.5555 0.42319 -0.45697 0.23784 0.74533
1996-11-28T22:08:04.5555 -0.84532 0.26974 -0.06532 0.45652
1996-11-30T01:28:02.5555 0.74563 -0.45375 0.36875 0.31964
DATA_STOP

META_START
COMMENT This block begins after trajectory correction maneuver TCM-3.
OBJECT_NAME       = mars_global_surveyor
OBJECT_ID         = 1996-062A
CENTER_NAME       = MARS BARYCENTER
REF_FRAME_A         = EME2000
REF_FRAME_B         = SC_BODY_1
TIME_SYSTEM       = UTC
START_TIME        = 1996-12-18T12:05:00.5555
USEABLE_START_TIME = 1996-12-18T12:10:00.5555
USEABLE_STOP_TIME  = 1996-12-28T21:23:00.5555
STOP_TIME         = 1996-12-28T21:28:00.5555
ATTITUDE_TYPE     = QUATERNION
META_STOP

DATA_START
1996-12-18T12:05:00.5555 -0.64585 0.018542 -0.23854 0.72501
1996-12-18T12:10:05.5555 0.87451 -0.43475 0.13458 0.16767
1996-12-18T12:10:10.5555 0.03125 -0.65874 0.23458 0.71418
1996-12-28T21:28:00.5555 -0.25485 0.58745 -0.36845 0.67394
DATA_STOP
"""


def _aem(version: str, meta: str, rows: str) -> str:
    return (f"CCSDS_AEM_VERS = {version}\nCREATION_DATE = 2023-06-01T00:00:00\nORIGINATOR = TEST\n\n"
            f"META_START\nOBJECT_NAME = SAT\nOBJECT_ID = 2023-001A\nTIME_SYSTEM = UTC\n"
            f"START_TIME = 2023-06-01T00:00:00\nSTOP_TIME = 2023-06-01T00:00:01\n{meta}META_STOP\n\n"
            f"DATA_START\n{rows}DATA_STOP\n")


def test_annex_f2_worked_example():
    """ADM 2.0 Annex F2.2: B = A turned +90 deg about Z; Q = (0, 0, 0.7071, 0.7071) 'from A to B';
    M_BA = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]; X_A = (1, 0, 0) has X_B = (0, -1, 0); the X axis of B
    has coordinates (0, 1, 0) in A."""
    text = _aem("2.0", "REF_FRAME_A = EME2000\nREF_FRAME_B = SC_BODY_1\nATTITUDE_TYPE = QUATERNION\n",
                "2023-06-01T00:00:00 0 0 0.7071 0.7071\n")
    q_AB = parse_aem(text).segments[0].q_AB[0]
    dcm_AB = rotations.quat_to_dcm(rotations.quat_normalize(q_AB))
    m_BA = dcm_AB.T
    np.testing.assert_allclose(m_BA, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-4)
    np.testing.assert_allclose(m_BA @ [1, 0, 0], [0, -1, 0], atol=1e-4)
    np.testing.assert_allclose(dcm_AB @ [1, 0, 0], [0, 1, 0], atol=1e-4)
    # Our q_AB is the CCSDS quaternion reordered (DESIGN.md): rotations.quat_from_ccsds agrees.
    np.testing.assert_array_equal(q_AB, rotations.quat_from_ccsds([0, 0, 0.7071, 0.7071]))


def test_figure_g4_example_parses():
    aem = parse_aem(AEM_G4)
    assert aem.version == "2.0" and aem.header["MESSAGE_ID"] == "A701523" and len(aem.segments) == 2
    s0, s1 = aem.segments
    assert s0.ref_frame_a == "EME2000" and s0.ref_frame_b == "SC_BODY_1" and len(s0.comments) == 3
    assert s0.metadata["INTERPOLATION_DEGREE"] == "7" and s1.comments == (
        "This block begins after trajectory correction maneuver TCM-3.",)
    np.testing.assert_array_equal(s0.q_AB[0], [0.68427, 0.56748, 0.03146, 0.45689])  # QC first here
    np.testing.assert_array_equal(s1.q_AB[-1], [0.67394, -0.25485, 0.58745, -0.36845])
    assert timescales.tai_ns_to_iso(s0.time_tai_ns[:1])[0] == "1996-11-28T21:29:07.255500Z"


def test_adm_1_quaternion_type_and_attitude_dir():
    q = rotations.quat_normalize(np.array([0.9, 0.1, -0.2, 0.3]))
    qc, q1, q2, q3 = (format_float(x) for x in q)
    head = "REF_FRAME_A = J2000\nREF_FRAME_B = SC_BODY_1\nATTITUDE_TYPE = QUATERNION\n"
    first, last = f"2023-06-01T00:00:00 {qc} {q1} {q2} {q3}\n", f"2023-06-01T00:00:00 {q1} {q2} {q3} {qc}\n"
    a2b_first = _aem("1.0", head + "ATTITUDE_DIR = A2B\nQUATERNION_TYPE = FIRST\n", first)
    a2b_last = _aem("1.0", head + "ATTITUDE_DIR = A2B\nQUATERNION_TYPE = LAST\n", last)
    b2a_first = _aem("1.0", head + "ATTITUDE_DIR = B2A\nQUATERNION_TYPE = FIRST\n", first)
    np.testing.assert_array_equal(parse_aem(a2b_first).segments[0].q_AB[0], q)
    np.testing.assert_array_equal(parse_aem(a2b_last).segments[0].q_AB[0], q)
    np.testing.assert_array_equal(parse_aem(b2a_first).segments[0].q_AB[0], rotations.quat_conjugate(q))
    with pytest.raises(AemError, match="QUATERNION_TYPE"):
        parse_aem(a2b_first.replace("QUATERNION_TYPE = FIRST\n", ""))
    with pytest.raises(AemError, match="ATTITUDE_DIR"):
        parse_aem(a2b_first.replace("ATTITUDE_DIR = A2B\n", ""))


def test_euler_angles_annex_f3_sequence():
    """ADM Annex F3: angles 'from A to B' are intrinsic rotations taking A into B; for XYZ,
    M_BA = R3(t3) R2(t2) R1(t1) (frame rotations). Our q_AB gives dcm_AB = M_BA^T."""
    t1, t2, t3 = np.radians([10.0, -20.0, 30.0])

    def r1(a):
        return np.array([[1, 0, 0], [0, np.cos(a), np.sin(a)], [0, -np.sin(a), np.cos(a)]])

    def r2(a):
        return np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])

    def r3(a):
        return np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])

    m_ba = r3(t3) @ r2(t2) @ r1(t1)
    q = quat_from_euler([[10.0, -20.0, 30.0]], "XYZ")[0]
    np.testing.assert_allclose(rotations.quat_to_dcm(q).T, m_ba, atol=1e-15)
    np.testing.assert_allclose(quat_from_euler([[10.0, -20.0, 30.0]], "123"), q[None], atol=1e-15)
    text = _aem("2.0", "REF_FRAME_A = GCRF\nREF_FRAME_B = SC_BODY_1\nATTITUDE_TYPE = EULER_ANGLE/ANGVEL\n"
                "EULER_ROT_SEQ = XYZ\nANGVEL_FRAME = SC_BODY_1\n", "2023-06-01T00:00:00 10 -20 30 0.1 0.2 0.3\n")
    seg = parse_aem(text).segments[0]
    np.testing.assert_allclose(seg.q_AB[0], q, atol=1e-15)
    np.testing.assert_array_equal(seg.extra, [[0.1, 0.2, 0.3]])


def _random_segment(n, seed, scale="UTC", **kw):
    rng = np.random.default_rng(seed)
    t = timescales.iso_to_tai_ns(["2016-12-31T23:59:58Z"])[0] + np.cumsum(rng.integers(1, 10**9, n))
    q = rotations.quat_normalize(rng.standard_normal((n, 4)))
    return aem_segment(t, q, object_name="SAT", object_id="2023-001A", ref_frame_a="GCRF",
                       ref_frame_b="SC_BODY_1", time_system=scale, **kw)


@pytest.mark.parametrize("scale", ["UTC", "TAI", "GPS", "TT"])
def test_aem_write_read_identical(scale):
    """Exported AEMs parse back identically (ns epochs across the 2016 leap second, every bit)."""
    segs = [_random_segment(50, 1, scale, comments=("first",)), _random_segment(7, 2, scale)]
    text = write_aem(segs, originator="TEST", creation_date=CREATED, message_id="M-1", comments=("hello",))
    back = parse_aem(text)
    assert back.version == "2.0" and back.header["MESSAGE_ID"] == "M-1" and back.comments == ("hello",)
    for a, b in zip(segs, back.segments, strict=True):
        np.testing.assert_array_equal(a.time_tai_ns, b.time_tai_ns)
        np.testing.assert_array_equal(a.q_AB, b.q_AB)
        assert a.metadata == b.metadata and a.comments == b.comments
    assert write_aem(list(back.segments), originator="TEST", creation_date=CREATED, message_id="M-1",
                     comments=("hello",)) == text
    if scale == "UTC":
        assert "2016-12-31T23:59:60." in text


def test_aem_cross_check_with_ccsds_ndm():
    ndm = pytest.importorskip("ccsds_ndm")
    seg = _random_segment(20, 3)
    text = write_aem([seg], originator="TEST", creation_date=CREATED)
    other = ndm.from_str(text).segments[0]
    assert other.metadata.ref_frame_a == "GCRF" and other.metadata.ref_frame_b == "SC_BODY_1"
    np.testing.assert_array_equal(other.data.attitude_states_numpy, rotations.quat_to_ccsds(seg.q_AB))
    assert list(other.data.attitude_states_epochs) == [x.rstrip("Z") for x in timescales.tai_ns_to_iso(seg.time_tai_ns)]


@pytest.mark.parametrize("text, match", [
    ("", "starts with CCSDS_AEM_VERS"),
    ("CCSDS_AEM_VERS = 3.0\n", "not supported"),
    (AEM_G4.replace("ORIGINATOR    = NASA/JPL\n", ""), "ORIGINATOR"),
    (AEM_G4.replace("OBJECT_ID         = 1996-062A\n", "", 1), "OBJECT_ID"),
    (AEM_G4.replace("ATTITUDE_TYPE     = QUATERNION", "ATTITUDE_TYPE = SPIN", 1), "ATTITUDE_TYPE 'SPIN'"),
    (AEM_G4.replace("0.56748 0.03146 0.45689 0.68427", "0.56748 0.03146 0.45689"), "needs 5 fields"),
    (AEM_G4.replace("0.56748 0.03146", "0.5x748 0.03146"), "must be numbers"),
    (AEM_G4.replace("0.56748 0.03146 0.45689 0.68427", "0.9 0.9 0.9 0.9"), "norm"),
    (AEM_G4.replace("1996-11-28T22:08:03.5555", "1996-11-28T21:29:07.2555"), "epochs must increase"),
    (AEM_G4.replace("TIME_SYSTEM       = UTC", "TIME_SYSTEM = TDB", 1), "TIME_SYSTEM 'TDB' is not supported"),
    (AEM_G4.replace("1996-11-28T22:08:03.5555", "1996-13-28T22:08:03"), "1996-13-28"),
    (AEM_G4.replace("DATA_STOP\n\nMETA_START", "\nMETA_START", 1), "unexpected"),
    (AEM_G4.replace("META_STOP\n\nDATA_START", "META_STOP\n", 1), "expected DATA_START"),
    (AEM_G4.replace("CENTER_NAME       = MARS BARYCENTER", "FOO = BAR", 1), "unexpected 'FOO = BAR'"),
])
def test_aem_errors_name_the_problem(text, match):
    with pytest.raises(KvnError, match=match):
        parse_aem(text)


def test_epochs_day_of_year_leap_second_and_extra_digits():
    t = parse_epochs(["2016-366T23:59:60.5", "2017-001T00:00:00Z", "2017-01-01T00:00:00.1234567891234"], "utc", "x")
    assert timescales.tai_ns_to_iso(t).tolist() == ["2016-12-31T23:59:60.500000000Z", "2017-01-01T00:00:00.000000000Z",
                                                   "2017-01-01T00:00:00.123456789Z"]
    with pytest.raises(ValueError, match="day of year 367"):
        parse_epochs(["2016-367T00:00:00"], "utc", "x")
    assert format_float(1e-5) == "1.0e-05" and float(format_float(0.1 + 0.2)) == 0.1 + 0.2
    with pytest.raises(ValueError, match="non-finite"):
        format_float(float("nan"))


# --- OEM ----------------------------------------------------------------------------------------


def test_oem_standard_example_values():
    oem = parse_oem((DATA / "oem_mgs_example.txt").read_text())
    assert oem.version == "3.0" and oem.header["ORIGINATOR"] == "NASA/JPL" and len(oem.segments) == 2
    s0, s1 = oem.segments
    assert s0.ref_frame == "J2000" and s0.time_system == "TAI" and s0.metadata["INTERPOLATION"] == "HERMITE"
    assert len(s0.data_comments) == 2 and s1.data_comments == ("This block begins after trajectory correction "
                                                               "maneuver TCM-3.",)
    np.testing.assert_array_equal(s0.position_km[0], [2789.619, -280.045, -1746.755])
    np.testing.assert_array_equal(s0.velocity_km_s[0], [4.73372, -2.49586, -1.04195])
    np.testing.assert_array_equal(s1.position_km[0], [-2432.166, -63.042, 1742.754])
    np.testing.assert_allclose(s0.position_m[0], [2789619.0, -280045.0, -1746755.0])
    assert timescales.tai_ns_to_iso(s0.time_tai_ns[:1], "tai")[0] == "1996-12-18T12:00:00.331"
    cov = s1.covariances[0]
    assert cov.ref_frame == "EME2000" and cov.matrix[0, 0] == 3.3313494e-04 and cov.matrix[5, 5] == 6.2244443e-10
    assert cov.matrix[0, 1] == cov.matrix[1, 0] == 4.6189273e-04
    assert not is_earth_fixed("J2000") and is_earth_fixed("ITRF2014") and is_earth_fixed("itrf-93")


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_oem_write_read_identical(version):
    oem = parse_oem((DATA / "oem_mgs_example.txt").read_text())
    text = write_oem(list(oem.segments), originator="NASA/JPL", version=version, creation_date=CREATED)
    back = parse_oem(text)
    assert back.version == version
    for a, b in zip(oem.segments, back.segments, strict=True):
        assert a.metadata == b.metadata and a.data_comments == b.data_comments
        for name in ("time_tai_ns", "position_km", "velocity_km_s"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert len(a.covariances) == len(b.covariances)
        for ca, cb in zip(a.covariances, b.covariances, strict=True):
            np.testing.assert_array_equal(ca.matrix, cb.matrix)
            assert ca.time_tai_ns == cb.time_tai_ns and ca.ref_frame == cb.ref_frame
    assert write_oem(list(back.segments), originator="NASA/JPL", version=version, creation_date=CREATED) == text


def test_oem_from_si_states_round_trip_and_cross_check(tmp_path):
    t = timescales.iso_to_tai_ns(["2023-06-01T00:00:00Z"])[0] + np.arange(5) * 10**9 + 123_456_789
    rng = np.random.default_rng(4)
    r = 7.0e6 * rng.standard_normal((5, 3))
    v = 7.5e3 * rng.standard_normal((5, 3))
    seg = oem_segment(t, r, v, object_name="SAT", object_id="2023-001A")
    text = write_oem([seg], originator="TEST", creation_date=CREATED)
    back = parse_oem(text).segments[0]
    np.testing.assert_array_equal(back.position_km, seg.position_km)
    np.testing.assert_allclose(back.position_m, r, rtol=1e-15)
    np.testing.assert_allclose(back.velocity_m_s, v, rtol=1e-15)
    oem_pkg = pytest.importorskip("oem")
    path = tmp_path / "x.oem"
    path.write_text(text)
    other = oem_pkg.OrbitEphemerisMessage.open(str(path))
    states = list(other.segments[0].states)
    assert other.segments[0].metadata["REF_FRAME"] == "ITRF" and len(states) == 5
    np.testing.assert_allclose(np.array([s.position for s in states]), seg.position_km, rtol=1e-15)
    np.testing.assert_allclose(np.array([s.velocity for s in states]), seg.velocity_km_s, rtol=1e-15)
    assert states[0].epoch.isot == "2023-06-01T00:00:00.123457"  # astropy's default 6 digits


@pytest.mark.parametrize("text, match", [
    ("CCSDS_OPM_VERS = 2.0\n", "starts with CCSDS_OEM_VERS"),
    ("CCSDS_OEM_VERS = 2.0\nORIGINATOR = X\nMETA_START\n", "CREATION_DATE"),
    ("CCSDS_OEM_VERS = 2.0\nCREATION_DATE = 2023-01-01T00:00:00\nORIGINATOR = X\nMETA_START\nOBJECT_NAME = A\n"
     "META_STOP\n", "mandatory keyword"),
])
def test_oem_errors(text, match):
    with pytest.raises(OemError, match=match):
        parse_oem(text)


def test_oem_data_errors():
    base = (DATA / "oem_mgs_example.txt").read_text()
    with pytest.raises(OemError, match="6 \\(or 9"):
        parse_oem(base.replace("2789.619 -280.045 -1746.755 4.73372", "2789.619 -280.045 4.73372"))
    with pytest.raises(OemError, match="lower-triangle"):
        parse_oem(base.replace("4.6189273e-04 6.7824216e-04\n", ""))
    with pytest.raises(OemError, match="COVARIANCE_STOP"):
        parse_oem(base.replace("COVARIANCE_STOP", ""))
    with pytest.raises(OemError, match="comments are allowed only before"):
        parse_oem(base.replace("1996-12-18T12:01:00.331", "COMMENT x\n1996-12-18T12:01:00.331"))
