"""RINEX 2/3 navigation parsing on the shared files (georinex test data, MIT licence)."""

from __future__ import annotations

import numpy as np
import pytest

from processing.formats.rinex_nav import RinexNavError, parse_rinex_nav, parse_rinex_nav_reference
from processing.time import timescales
from tests.real_data import GNSS_NAV

NAV_DIR = GNSS_NAV
RINEX2 = NAV_DIR / "brdc2800.15n"
RINEX3 = NAV_DIR / "BRDM00DLR_R_20130010000_01D_MN.rnx"


@pytest.fixture(scope="module")
def nav2():
    return parse_rinex_nav(RINEX2.read_bytes())


@pytest.fixture(scope="module")
def nav3():
    return parse_rinex_nav(RINEX3.read_bytes())


def _iso(t: int) -> str:
    return str(timescales.tai_ns_to_iso(np.array([t], np.int64), scale="utc")[0])


def test_rinex2_gps_file(nav2) -> None:
    c = nav2.columns
    assert nav2.version == 2.0 and nav2.file_system == "G" and nav2.leap_seconds == 17
    assert nav2.n_records == 420
    assert sorted(set(c["sat"])) == [f"G{k:02d}" for k in range(1, 33)]
    i = np.flatnonzero(c["sat"] == "G01")[0]
    # first record of the file: " 1 15 10  7  0  0  0.0 0.187428668141D-05 ..." (GPS time)
    assert _iso(c["time_tai_ns"][i]) == "2015-10-06T23:59:43Z"  # 00:00:00 GPST, 17 leap seconds
    assert c["af0_s"][i] == 0.187428668141e-05 and c["af1_s_s"][i] == 0.795807864051e-12
    assert c["iode"][i] == 70.0 and c["crs_m"][i] == -67.34375
    assert c["sqrt_a_sqrt_m"][i] == 0.515366233826e04 and c["e"][i] == 0.475465832278e-02
    assert c["toe_s"][i] == 259200.0 and c["week"][i] == 1865.0
    assert c["i0_rad"][i] == 0.962769186081 and c["omega_dot_rad_s"][i] == -0.804783528707e-08
    assert c["ref_tai_ns"][i] == c["time_tai_ns"][i]  # toe = toc for this record
    assert np.all(np.isnan(c["x_m"]))


def test_rinex3_mixed_file(nav3) -> None:
    c = nav3.columns
    assert nav3.version == 3.02 and nav3.file_system == "M" and nav3.leap_seconds == 16
    assert c["sat"].tolist() == ["G01", "G01", "G02", "G02", "J01", "J01", "R01", "R01", "R02", "R02"]
    r01 = np.flatnonzero(c["sat"] == "R01")[0]
    # "R01 2013 01 01 00 15 00-1.750094816089e-04 0.000000000000e+00 1.728000000000e+05", UTC
    assert _iso(c["time_tai_ns"][r01]) == "2013-01-01T00:15:00Z"
    assert c["x_m"][r01] == pytest.approx(8450.493652344e3, abs=1e-6)
    assert c["vx_m_s"][r01] == pytest.approx(1.381167411804e3, abs=1e-9)
    assert c["z_m"][r01] == pytest.approx(15109.79541016e3, abs=1e-6)
    assert c["freq_channel"][r01] == 1.0 and c["health"][r01] == 0.0
    assert c["af0_s"][r01] == -1.750094816089e-04
    r02 = np.flatnonzero(c["sat"] == "R02")[0]
    assert c["freq_channel"][r02] == -4.0
    g01 = np.flatnonzero(c["sat"] == "G01")[0]
    assert _iso(c["time_tai_ns"][g01]) == "2013-01-01T01:59:44Z"  # 02:00:00 GPST, 16 leap seconds
    assert c["toe_s"][g01] == 1.8e5 and c["week"][g01] == 1721.0
    j01 = np.flatnonzero(c["sat"] == "J01")
    assert c["health"][j01].tolist() == [1.0, 1.0]
    # QZSS toe of the second record, 177312 s of GPS week 1721 (epoch 01:15:12 GPST)
    assert _iso(c["ref_tai_ns"][j01[1]]) == "2013-01-01T01:14:56Z"


def test_reference_parser_span_and_details() -> None:
    parsed = parse_rinex_nav_reference(RINEX3.read_bytes())
    assert parsed.details["systems"] == ["G", "J", "R"] and parsed.details["n_records"] == 10
    ref = parsed.columns["ref_tai_ns"]
    assert parsed.start_tai_ns < ref.min() and parsed.end_tai_ns > ref.max()
    assert parsed.end_tai_ns - ref.max() == 7200 * 10**9  # GPS/QZSS validity dominates


def test_malformed_files() -> None:
    with pytest.raises(RinexNavError, match="RINEX header"):
        parse_rinex_nav(b"hello\n")
    text = RINEX3.read_text().splitlines()
    with pytest.raises(RinexNavError, match="truncated"):
        parse_rinex_nav("\n".join(text[:16]) + "\n")
    bad = list(text)
    bad[13] = bad[13][:30] + "x" * 8 + bad[13][38:]
    with pytest.raises(RinexNavError, match="line 14"):
        parse_rinex_nav("\n".join(bad))
    obs = "     3.02           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE\n"
    with pytest.raises(RinexNavError, match="not navigation data"):
        parse_rinex_nav(obs)
