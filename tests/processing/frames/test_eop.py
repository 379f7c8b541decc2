"""IERS finals2000A parsing and Earth-orientation interpolation (processing/frames/eop.py).

tests/data/finals2000A_2017-01-01_04.txt: four verbatim rows of the IERS finals2000A.data file (see
tests/data/README.md); expected values below are read off that text.
"""


import numpy as np
import pytest

from processing.frames.earth_orientation import EarthOrientation, gcrs_to_itrs_mat
from processing.frames.eop import (
    EopCoverageError,
    EopFormatError,
    interpolate_eop,
    lagrange4,
    parse_finals2000a,
    parse_finals2000a_reference,
)
from processing.time import timescales
from processing.time.julian_dates import tai_ns_to_ut1_jd
from processing.units import RAD_PER_ARCSEC
from tests.real_data import REFERENCE

DATA = REFERENCE / "finals2000A_2017-01-01_04.txt"
ROW1 = DATA.read_text().splitlines()[0]


def test_parse_real_rows_uses_bulletin_b_values_from_the_text():
    c = parse_finals2000a(DATA.read_bytes())
    np.testing.assert_array_equal(c["mjd_utc"], [57754.0, 57755.0, 57756.0, 57757.0])
    # Row 1: Bulletin B PM-x 0.080450, PM-y 0.263074, UT1-UTC 0.5912975, dX -0.019, dY -0.057; LOD (A) 1.0342.
    assert c["xp_arcsec"][0] == 0.080450 and c["yp_arcsec"][0] == 0.263074
    assert c["dut1_s"][0] == 0.5912975 and c["lod_ms"][0] == 1.0342
    assert c["dx_mas"][0] == -0.019 and c["dy_mas"][0] == -0.057
    assert c["dut1_s"][3] == 0.5875625
    assert list(c["pm_source"]) == ["B"] * 4 and list(c["ut1_source"]) == ["B"] * 4
    # 2017-01-01 00:00:00 UTC (just after the leap second: TAI-UTC = 37 s)
    assert timescales.tai_ns_to_iso(c["time_tai_ns"][:1])[0] == "2017-01-01T00:00:00Z"
    np.testing.assert_allclose(c["ut1_minus_tai_s"], c["dut1_s"] - 37.0, rtol=0, atol=1e-12)


def test_bulletin_a_used_where_b_is_blank_and_predictions_flagged():
    a_only = ROW1[:134]  # drop the Bulletin B columns 135-185
    predicted = a_only.replace("57754.00 I", "57755.00 P").replace("17 1 1", "17 1 2").replace("  I 0.59", "  P 0.59")
    future = "17 1 3 57756.00"
    c = parse_finals2000a(f"{a_only}\n\n{predicted}\n{future}\n".encode())
    assert c["mjd_utc"].tolist() == [57754.0, 57755.0]  # the date-only future row is dropped
    assert c["xp_arcsec"][0] == 0.080504 and c["yp_arcsec"][0] == 0.263145 and c["dut1_s"][0] == 0.5912821
    assert c["pm_source"].tolist() == ["I", "P"] and c["ut1_source"].tolist() == ["I", "P"]
    ref = parse_finals2000a_reference(f"{a_only}\n{predicted}\n".encode())
    assert ref.details["predicted_rows"] == 1 and ref.details["first_predicted_mjd_utc"] == 57755.0
    assert ref.start_tai_ns == int(c["time_tai_ns"][0]) and ref.end_tai_ns == int(c["time_tai_ns"][1])


@pytest.mark.parametrize("raw, match", [
    (b"", "at least 2 daily rows"),
    (b"garbage\n", "too short"),
    (("17 1 1 5775x.00" + ROW1[15:]).encode(), "MJD .columns 8-15. should be a number"),
    (ROW1.replace(" 0.080504", " 0.08x504").encode() + b"\n" + ROW1.encode(), "PM-x"),
    ((ROW1 + "\n" + ROW1).encode(), "appears twice"),
    ("17 1 1 57754.00 I  0,080504".encode("latin-1") + "\xe9".encode("latin-1"), "ASCII"),
])
def test_bad_files_say_what_and_where(raw, match):
    with pytest.raises(EopFormatError, match=match):
        parse_finals2000a(raw)


def test_interpolation_reproduces_nodes_and_is_cubic_between():
    c = parse_finals2000a(DATA.read_bytes())
    e = interpolate_eop(c, c["time_tai_ns"], source="test")
    np.testing.assert_allclose(e.dut1_s, c["dut1_s"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(e.xp_rad, c["xp_arcsec"] * RAD_PER_ARCSEC, rtol=0, atol=1e-18)
    assert e.source == "test"
    # 4-point Lagrange reproduces cubics exactly.
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.5])
    y = 2.0 - x + 0.5 * x**2 - 0.1 * x**3
    xq = np.linspace(0, 4.5, 11)
    np.testing.assert_allclose(lagrange4(x, y, xq), 2.0 - xq + 0.5 * xq**2 - 0.1 * xq**3, atol=1e-12)
    np.testing.assert_allclose(lagrange4(x[:2], y[:2], np.array([0.5])), [0.5 * (y[0] + y[1])])


def test_interpolation_across_a_leap_second_is_continuous_in_ut1():
    """UT1-UTC jumps by +1 s at 2016-12-31T23:59:60; interpolating UT1-TAI keeps UT1 continuous."""
    days = ["2016-12-30", "2016-12-31", "2017-01-01", "2017-01-02"]
    t = timescales.iso_to_tai_ns([f"{d}T00:00:00Z" for d in days])
    ut1_minus_tai = -36.4 - 0.001 * np.arange(4)  # smooth, 1 ms/day
    dut1 = ut1_minus_tai + timescales.tai_minus_utc_s(t)  # -0.4 s before, +0.6 s after the leap second
    cols = {"time_tai_ns": t, "xp_arcsec": np.zeros(4), "yp_arcsec": np.zeros(4), "ut1_minus_tai_s": ut1_minus_tai}
    around = timescales.iso_to_tai_ns(["2016-12-31T23:59:59.5Z", "2016-12-31T23:59:60.5Z", "2017-01-01T00:00:00.5Z"])
    e = interpolate_eop(cols, around)
    assert dut1[1] < -0.39 and dut1[2] > 0.59
    np.testing.assert_allclose(e.dut1_s, [-0.402, -0.402, 0.598], atol=1e-4)
    ut1 = [tai_ns_to_ut1_jd(np.int64(x), d) for x, d in zip(around, e.dut1_s, strict=True)]
    ut1_s = np.array([(a - 2457753.5 + b) * 86400.0 for a, b in ut1])
    np.testing.assert_allclose(np.diff(ut1_s), [1.0, 1.0], atol=1e-6)  # UT1 advances 1 s per TAI second


def test_coverage_error_and_shapes():
    c = parse_finals2000a(DATA.read_bytes())
    inside = c["time_tai_ns"][0] + np.array([[0, 3600], [7200, 10800]]) * 10**9
    e = interpolate_eop(c, inside)
    assert e.dut1_s.shape == (2, 2) and e.xp_rad.shape == (2, 2)
    m = gcrs_to_itrs_mat(inside, e)
    assert m.shape == (2, 2, 3, 3)
    with pytest.raises(EopCoverageError, match="covers 2017-01-01T00:00:00Z .. 2017-01-04"):
        interpolate_eop(c, c["time_tai_ns"][-1:] + 1)


def test_eop_changes_the_earth_rotation_by_the_expected_angle():
    """UT1-UTC = 0.59 s turns the Earth by w dt = 4.3e-5 rad about the pole relative to zero EOP."""
    c = parse_finals2000a(DATA.read_bytes())
    t = c["time_tai_ns"][1:2] + 6 * 3600 * 10**9
    e = interpolate_eop(c, t)
    m0 = gcrs_to_itrs_mat(t, EarthOrientation())
    m1 = gcrs_to_itrs_mat(t, EarthOrientation(dut1_s=e.dut1_s))
    d = m1[0] @ m0[0].T
    angle = np.arctan2(d[0, 1], d[0, 0])
    np.testing.assert_allclose(angle, 7.2921151467e-5 * float(e.dut1_s[0]) * 1.0, rtol=1e-3)
