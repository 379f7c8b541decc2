"""GRACE-FO Level-1B readers on the 2023-06-01 samples in data/; expected values are copied from the
files' text (first/last data rows) and their YAML headers."""


import numpy as np
import pytest

from processing.attitude import rotations
from processing.formats import gracefo_l1b as l1b
from processing.time import timescales
from tests.real_data import GRACEFO

DATA = GRACEFO


def _read(product: str, sat: str = "C") -> l1b.L1bFile:
    return l1b.parse_l1b((DATA / f"{product}_2023-06-01_{sat}_04.txt").read_bytes())


def test_time_origin_is_2000_01_01_noon_gps():
    # "Continuous seconds past 01-Jan-2000 11:59:47 UTC" = 12:00:00 GPS; TAI = GPS + 19 s.
    assert timescales.tai_ns_to_iso(np.array([l1b.GPS_EPOCH_2000_TAI_NS]))[0] == "2000-01-01T11:59:47Z"
    assert timescales.tai_ns_to_iso(np.array([l1b.GPS_EPOCH_2000_TAI_NS]), "gps")[0] == "2000-01-01T12:00:00"


def test_sca1b_first_and_last_rows():
    f = _read("SCA1B")
    assert f.product == "SCA1B" and f.satellite == "C" and f.n_rows == 100
    assert f.header["global_attributes"]["summary"].endswith("rotation quaternions from Inertial Frame to SRF")
    t, q = l1b.sca_quaternions(f)
    # 738849600 C 23 0.07816222822585139 0.1642723922577685 -0.004109730449778668 0.9833048140804912 ...
    np.testing.assert_array_equal(q[0], [0.07816222822585139, 0.1642723922577685, -0.004109730449778668,
                                         0.9833048140804912])
    # 738849699 C 23 0.07831234817801695 0.1102557502990408 0.0002341758629126803 0.9908131966420206
    np.testing.assert_array_equal(q[-1], [0.07831234817801695, 0.1102557502990408, 0.0002341758629126803,
                                          0.9908131966420206])
    assert timescales.tai_ns_to_iso(t[:1], "gps")[0] == "2023-06-01T00:00:00"  # GPS 738849600 s after the origin
    assert timescales.tai_ns_to_iso(t[:1])[0] == "2023-05-31T23:59:42Z"  # GPS - 18 s = UTC in 2023
    assert timescales.tai_ns_to_iso(t[-1:], "gps")[0] == "2023-06-01T00:01:39"  # 738849699
    assert f.columns["sca_id"][0] == 23 and f.columns["qualflg"][0] == "00000000"


def test_sca1b_c_and_d_fly_facing_each_other():
    """GRACE-FO D's quaternion is C's turned by 180 deg about the SRF z axis (to ~1.5 deg: the two
    line-of-sight pitch offsets): the two spacecraft point their K-band horns (+X) at each other."""
    _, q_c = l1b.sca_quaternions(_read("SCA1B", "C"))
    _, q_d = l1b.sca_quaternions(_read("SCA1B", "D"))
    q_rel = rotations.quat_multiply(rotations.quat_conjugate(q_c), q_d)  # q_{S_C S_D}
    angle = np.degrees(rotations.quat_angle(q_rel))
    axis = q_rel[:, 1:] / np.linalg.norm(q_rel[:, 1:], axis=1)[:, None]
    assert np.all(np.abs(angle - 180.0) < 0.1) and np.all(np.abs(np.abs(axis[:, 2]) - 1.0) < 1e-3)


def test_gnv1b_first_row_earth_fixed():
    f = _read("GNV1B")
    t, r, v, frame = l1b.gnv_states(f)
    # 738849600 C E 562516.6928322315 -2051148.109060925 -6546817.760876593 ... -1636.58495865621
    # 7025.557923232562 -2348.304620900529
    assert frame == "E" and t.size == 100
    np.testing.assert_array_equal(r[0], [562516.6928322315, -2051148.109060925, -6546817.760876593])
    np.testing.assert_array_equal(v[0], [-1636.58495865621, 7025.557923232562, -2348.304620900529])
    assert 6.7e6 < np.linalg.norm(r[0]) < 6.9e6  # ~490 km altitude
    np.testing.assert_array_equal(np.diff(t), 10**9)


def test_imu1b_angles_rates_and_increments():
    f = _read("IMU1B")
    t, a, notes = l1b.imu_angles(f)
    # Gyros 2 and 3 start 1-2 ms after gyro 1 (738849600 109131 / 110262 / 111377 us), so the first
    # common epoch is gyro 1's second one: 738849600 234127 G C 1 -3213.26668073817, with gyro 2
    # interpolated between 2091.53854510316 (110262 us) and 2091.53855580007 (235255 us).
    assert timescales.tai_ns_to_iso(t[:1], "gps")[0] == "2023-06-01T00:00:00.234127"
    assert a[0, 0] == np.radians(-3213.26668073817)
    assert abs(a[0, 1] - np.radians(2091.53855580007)) < np.radians(1e-7)
    assert notes == ()
    tr, w = l1b.imu_rates(t, a)
    assert tr.size == t.size - 2
    # Orbital-rate magnitudes on axes 1 and 3 (~0.05 deg/s), about zero on axis 2.
    np.testing.assert_allclose(np.degrees(w[:, 0]).mean(), 0.0517, atol=5e-4)
    assert abs(np.degrees(w[:, 1]).mean()) < 1e-3
    ti, inc, dt = l1b.imu_increments(t, a)
    np.testing.assert_allclose(np.sum(inc, axis=0), a[-1] - a[0], atol=1e-12)
    np.testing.assert_allclose(dt, 0.125, atol=0.005)  # 8 Hz


def test_mag1b_field_in_nanotesla_and_microsecond_fraction():
    f = _read("MAG1B")
    t, b, notes = l1b.mag_field_nt(f)
    # 738849600 83329 C G 12.32833957672119 7.117527008056641 -31.84239959716797 (microtesla)
    np.testing.assert_allclose(b[0], [12328.33957672119, 7117.527008056641, -31842.39959716797], rtol=1e-15)
    assert timescales.tai_ns_to_iso(t[:2], "gps").tolist() == ["2023-06-01T00:00:00.083329",
                                                               "2023-06-01T00:00:00.583329"]
    assert "microseconds" in notes[0]


def test_bad_files():
    with pytest.raises(l1b.GraceFoFormatError, match="End of YAML header"):
        l1b.parse_l1b(b"738849600 C 23 1 0 0 0\n")
    text = (DATA / "SCA1B_2023-06-01_C_04.txt").read_text()
    with pytest.raises(l1b.GraceFoFormatError, match="data row 1 has 8 fields"):
        l1b.parse_l1b(text.replace(" 8.773305180563576e-07", "", 1).encode())
    with pytest.raises(l1b.GraceFoFormatError, match="not a number"):
        l1b.parse_l1b(text.replace("0.07816222822585139", "0.0781x", 1).encode())
    with pytest.raises(l1b.GraceFoFormatError, match="no data rows"):
        l1b.parse_l1b(text.split("# End of YAML header")[0].encode() + b"# End of YAML header\n")
    with pytest.raises(l1b.GraceFoFormatError, match="unknown product"):
        l1b.parse_l1b(text.replace("quatangle", "something").encode())
    with pytest.raises(l1b.GraceFoFormatError, match="expected GNV1B"):
        l1b.gnv_states(_read("SCA1B"))
