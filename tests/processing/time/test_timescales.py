"""Tests of processing.time.timescales against published leap seconds, ERFA's own routines and GPS facts.

Authorities:
- IERS Bulletin C (https://hpiers.obspm.fr/iers/bul/bulc/): no. 49 announced the leap second at
  the end of 2015-06-30 (TAI-UTC 35 s -> 36 s), no. 52 the one at the end of 2016-12-31
  (36 s -> 37 s), no. 53 that none would be inserted at the end of 2017-06-30. The full history
  1972-2017 below is the IERS file leap-seconds.list (TAI-UTC from the given date on).
- ERFA (liberfa, = IAU SOFA) scalar routines through pyerfa: dtf2d, utctai, taiutc, taitt,
  utcut1, d2dtf; a few hundred random times 1972-2030 including leap-second days.
- GPS: IS-GPS-200 sec. 3.3.4: GPS time started at 1980-01-06T00:00:00 UTC, when TAI-UTC was 19 s,
  so GPS = TAI - 19 s. The week number and second of week below are computed from that rule, and
  the GPS week 1024 rollover (to week 2048) at 2019-04-06T23:59:42 UTC is the US Coast Guard
  Navigation Center's published instant.
"""

from __future__ import annotations

import bisect
import datetime as dt
import warnings

import erfa
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from processing.time.julian_dates import tai_ns_from_jd, tai_ns_to_jd, tai_ns_to_ut1_jd
from processing.time.timescales import (
    SCALES,
    TAI_MINUS_GPS_S,
    TT_MINUS_TAI_S,
    TimeValueError,
    epoch_ns_to_tai_ns,
    iso_to_tai_ns,
    seconds_to_tai_ns,
    tai_minus_utc_s,
    tai_ns_to_epoch_ns,
    tai_ns_to_iso,
    tai_ns_to_seconds,
    utc_leap_second_dates,
)
from processing.units import NS_PER_S

DAY_NS = 86_400 * NS_PER_S
MICROSECOND_S = 1e-6

# IERS leap-seconds.list: (first UTC day with the new offset, TAI-UTC in s from then on).
IERS_TAI_MINUS_UTC = [
    ("1972-01-01", 10), ("1972-07-01", 11), ("1973-01-01", 12), ("1974-01-01", 13), ("1975-01-01", 14),
    ("1976-01-01", 15), ("1977-01-01", 16), ("1978-01-01", 17), ("1979-01-01", 18), ("1980-01-01", 19),
    ("1981-07-01", 20), ("1982-07-01", 21), ("1983-07-01", 22), ("1985-07-01", 23), ("1988-01-01", 24),
    ("1990-01-01", 25), ("1991-01-01", 26), ("1992-07-01", 27), ("1993-07-01", 28), ("1994-07-01", 29),
    ("1996-01-01", 30), ("1997-07-01", 31), ("1999-01-01", 32), ("2006-01-01", 33), ("2009-01-01", 34),
    ("2012-07-01", 35), ("2015-07-01", 36), ("2017-01-01", 37),
]
IERS_STARTS_S = [int(np.datetime64(d, "s").astype(np.int64)) for d, _ in IERS_TAI_MINUS_UTC]
LEAP_DAYS = [np.datetime64(d, "D") - 1 for d, _ in IERS_TAI_MINUS_UTC[1:]]
UNIX_2017_S = 1_483_228_800  # 2017-01-01T00:00:00 as a POSIX count (17167 days)
TAI_1972_NS = (IERS_STARTS_S[0] + 10) * NS_PER_S  # 1972-01-01T00:00:00 UTC as tai_ns
TAI_2036_NS = int(np.datetime64("2036-01-01", "s").astype(np.int64) + 37) * NS_PER_S


def iers_tai_minus_utc_s(posix_s: float) -> int:
    """TAI-UTC at a UTC reading given as a POSIX count, from the IERS list above."""
    return IERS_TAI_MINUS_UTC[bisect.bisect_right(IERS_STARTS_S, posix_s) - 1][1]


def quiet_erfa(fn, *args):
    """Call an ERFA authority routine without its "dubious year" warnings for years after 2028
    (ERFA's own table-age check); our module never calls ERFA per sample and warns for nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        return fn(*args)


def jd_diff_s(a: tuple, b: tuple) -> np.ndarray:
    return np.abs((np.asarray(a[0]) - b[0]) + (np.asarray(a[1]) - b[1])) * 86_400.0


# ---------------------------------------------------------------------------------- leap seconds


@pytest.mark.parametrize(
    ("day", "before_s", "bulletin"),
    [("2016-12-31", 36, "Bulletin C 52"), ("2015-06-30", 35, "Bulletin C 49")],
)
def test_leap_second_readings_are_one_second_apart(day, before_s, bulletin):
    nxt = str(np.datetime64(day) + 1)
    strings = [f"{day}T23:59:59Z", f"{day}T23:59:60Z", f"{day}T23:59:60.5Z", f"{nxt}T00:00:00Z"]
    t = iso_to_tai_ns(strings)
    np.testing.assert_array_equal(np.diff(t), [NS_PER_S, NS_PER_S // 2, NS_PER_S // 2])
    np.testing.assert_array_equal(tai_minus_utc_s(t), [before_s] * 3 + [before_s + 1])  # bulletin
    midnight_s = int(np.datetime64(nxt, "s").astype(np.int64))
    assert t[-1] == (midnight_s + before_s + 1) * NS_PER_S
    assert list(tai_ns_to_iso(t)) == [
        f"{day}T23:59:59.000Z", f"{day}T23:59:60.000Z", f"{day}T23:59:60.500Z", f"{nxt}T00:00:00.000Z"]


def test_2017_anchor_is_posix_plus_37_s():
    t = iso_to_tai_ns(["2017-01-01T00:00:00Z"])
    assert t[0] == (UNIX_2017_S + 37) * NS_PER_S
    assert tai_ns_to_seconds(t, "utc")[0] == UNIX_2017_S
    assert tai_ns_to_iso(t, "tai")[0] == "2017-01-01T00:00:37"


def test_no_leap_second_at_end_of_2017_06_30():  # Bulletin C 53
    with pytest.raises(TimeValueError, match="row 0: 23:59:60 on 2017-06-30 is not a leap second") as err:
        iso_to_tai_ns(["2017-06-30T23:59:60Z"])
    assert err.value.rows == [(0, "23:59:60 on 2017-06-30 is not a leap second")]


def test_erfa_table_matches_iers_history():
    np.testing.assert_array_equal(utc_leap_second_dates()[: len(LEAP_DAYS)], LEAP_DAYS)
    readings = [f"{d}T00:00:00Z" for d, _ in IERS_TAI_MINUS_UTC]
    np.testing.assert_array_equal(tai_minus_utc_s(iso_to_tai_ns(readings)), [s for _, s in IERS_TAI_MINUS_UTC])


def test_leap_second_with_zone_offsets():
    t = iso_to_tai_ns(["2016-12-31T23:59:60.25Z", "2017-01-01T00:59:60.25+01:00", "2016-12-31 18:59:60.25-05:00"])
    assert len(set(t.tolist())) == 1
    with pytest.raises(TimeValueError, match="row 0: .* has second 60 outside 23:59:60 UTC"):
        iso_to_tai_ns(["2016-12-31T23:59:60+01:00"])


def test_every_leap_second_of_the_table_round_trips():
    strings = [f"{d}T23:59:60.999999999Z" for d in LEAP_DAYS]
    t = iso_to_tai_ns(strings)
    assert list(tai_ns_to_iso(t)) == strings
    np.testing.assert_array_equal(tai_minus_utc_s(t), [s for _, s in IERS_TAI_MINUS_UTC[:-1]])
    # POSIX seconds hold at the following midnight during the leap second.
    np.testing.assert_array_equal(tai_ns_to_seconds(t, "utc"), IERS_STARTS_S[1:])


def test_beyond_the_table_the_last_offset_applies_without_warnings():
    t = iso_to_tai_ns(["2035-06-30T12:00:00Z", "2261-12-31T23:59:59Z"])
    np.testing.assert_array_equal(tai_minus_utc_s(t), [37, 37])
    assert list(tai_ns_to_iso(t)) == ["2035-06-30T12:00:00Z", "2261-12-31T23:59:59Z"]
    jd1, jd2 = tai_ns_to_jd(t, "utc")  # erfa.dtf2d would warn "dubious year" here; we must not
    assert jd1[0] == 2440587.5 + (np.datetime64("2035-06-30") - np.datetime64("1970-01-01")).astype(int)
    assert jd2[0] == 0.5


def test_an_updated_erfa_table_is_used():
    original = erfa.leap_seconds.get().copy()
    try:
        erfa.leap_seconds.update(np.array([(2031, 1, 38.0)], dtype=original.dtype))
        t = iso_to_tai_ns(["2030-12-31T23:59:60Z", "2031-01-01T00:00:00Z"])
        assert np.diff(t)[0] == NS_PER_S
        np.testing.assert_array_equal(tai_minus_utc_s(t), [37, 38])
        assert utc_leap_second_dates()[-1] == np.datetime64("2030-12-31")
    finally:
        erfa.leap_seconds.set(original)
    with pytest.raises(TimeValueError, match="23:59:60 on 2030-12-31 is not a leap second"):
        iso_to_tai_ns(["2030-12-31T23:59:60Z"])


# ------------------------------------------------------------------------------- against ERFA


def random_utc_fields(rng: np.random.Generator, n: int):
    """n random UTC times 1972-2030 (whole microseconds), a third of them in leap seconds."""
    first, last = np.datetime64("1972-01-01"), np.datetime64("2030-12-31")
    days = first + rng.integers(0, (last - first).astype(int) + 1, n)
    n_leap = n // 3
    days[:n_leap] = rng.choice(np.array(LEAP_DAYS), n_leap)
    sec_of_day = rng.integers(0, 86_400, n)
    sec_of_day[:n_leap] = 86_400  # 23:59:60
    micro = rng.integers(0, 1_000_000, n)
    ymd = days.astype(str)
    y, m, d = (np.array([int(s.split("-")[k]) for s in ymd]) for k in range(3))
    hour = np.minimum(sec_of_day // 3600, 23)
    minute = np.minimum((sec_of_day - hour * 3600) // 60, 59)
    second = sec_of_day - hour * 3600 - minute * 60
    iso = [f"{a}T{h:02d}:{mi:02d}:{s:02d}.{u:06d}Z"
           for a, h, mi, s, u in zip(ymd, hour, minute, second, micro, strict=True)]
    return iso, (y, m, d, hour, minute, second + micro * 1e-6)


def test_parse_and_julian_dates_match_erfa():
    iso, fields = random_utc_fields(np.random.default_rng(20170101), 400)
    u1, u2 = quiet_erfa(erfa.dtf2d, "UTC", *fields)
    a1, a2 = quiet_erfa(erfa.utctai, u1, u2)
    t1, t2 = erfa.taitt(a1, a2)
    tai = iso_to_tai_ns(iso)
    assert jd_diff_s(tai_ns_to_jd(tai, "utc"), (u1, u2)).max() < MICROSECOND_S
    assert jd_diff_s(tai_ns_to_jd(tai, "tai"), (a1, a2)).max() < MICROSECOND_S
    assert jd_diff_s(tai_ns_to_jd(tai, "tt"), (t1, t2)).max() < MICROSECOND_S
    for scale, jd in (("utc", (u1, u2)), ("tai", (a1, a2)), ("tt", (t1, t2))):
        assert np.abs(tai_ns_from_jd(*jd, scale) - tai).max() < 1_000  # ns


def test_format_matches_erfa_d2dtf():
    rng = np.random.default_rng(2015_06_30)
    n = 300
    micro = rng.integers(0, 59 * 365 * 86_400 * 10**6, n) + TAI_1972_NS // 1000
    # TAI at the start of each 23:59:60: the next midnight's POSIX count plus the old TAI-UTC.
    leap_tai_s = np.array([s + off for s, (_, off) in zip(IERS_STARTS_S[1:], IERS_TAI_MINUS_UTC[:-1], strict=True)])
    micro[: n // 3] = rng.choice(leap_tai_s, n // 3) * 10**6 + rng.integers(0, 10**6, n // 3)
    tai = micro * 1000
    assert np.any(micro % 1000)  # so the output has exactly 6 digits
    a1 = 2440587.5 + (tai // DAY_NS).astype(float)  # TAI JD split by hand, exactly
    a2 = (tai % DAY_NS) / DAY_NS
    u1, u2 = quiet_erfa(erfa.taiutc, a1, a2)
    t1, t2 = erfa.taitt(a1, a2)
    for scale, jd, zone in (("utc", (u1, u2), "Z"), ("tai", (a1, a2), ""), ("tt", (t1, t2), "")):
        y, mo, d, hmsf = quiet_erfa(erfa.d2dtf, scale.upper(), 6, *jd)
        expected = [f"{a:04d}-{b:02d}-{c:02d}T{h:02d}:{m:02d}:{s:02d}.{f:06d}{zone}"
                    for a, b, c, (h, m, s, f) in zip(y, mo, d, hmsf, strict=True)]
        assert list(tai_ns_to_iso(tai, scale)) == expected
    assert sum(s[17:19] == "60" for s in tai_ns_to_iso(tai)) == n // 3


def test_ut1_matches_erfa_utcut1():
    iso, fields = random_utc_fields(np.random.default_rng(7), 200)
    u1, u2 = quiet_erfa(erfa.dtf2d, "UTC", *fields)
    dut1 = np.random.default_rng(8).uniform(-0.9, 0.9, len(iso))
    tai = iso_to_tai_ns(iso)
    assert jd_diff_s(tai_ns_to_ut1_jd(tai, dut1), quiet_erfa(erfa.utcut1, u1, u2, dut1)).max() < MICROSECOND_S
    assert jd_diff_s(tai_ns_to_ut1_jd(tai), quiet_erfa(erfa.utcut1, u1, u2, 0.0)).max() < MICROSECOND_S


# ------------------------------------------------------------------------------------ GPS, TT


def test_gps_epoch_and_weeks():
    week_s = 7 * 86_400
    gps_epoch_s = 3657 * 86_400  # 1970-01-01 to 1980-01-06 is 3657 days: 315964800 s
    t = iso_to_tai_ns(["1980-01-06T00:00:00Z", "2017-01-01T00:00:00Z", "2019-04-06T23:59:42Z"])
    assert tai_ns_to_iso(t[:1], "gps")[0] == "1980-01-06T00:00:00"
    assert tai_ns_to_iso(t[:1], "tai")[0] == "1980-01-06T00:00:19"
    gps_s = tai_ns_to_seconds(t, "gps") - gps_epoch_s
    # 2017-01-01 (a Sunday) starts week 1930: 13510 days after 1980-01-06; GPS-UTC = 37 - 19 = 18 s.
    assert divmod(gps_s[1], week_s) == (1930, 18)
    assert divmod(gps_s[2], week_s) == (2048, 0)  # the 2019 rollover (USCG NAVCEN)
    assert gps_s[0] == 0
    np.testing.assert_array_equal(seconds_to_tai_ns(gps_s + gps_epoch_s, "gps"), t)


def test_scale_readings_of_one_instant():
    t = iso_to_tai_ns(["2017-01-01T00:00:00Z"])[0]
    assert iso_to_tai_ns(["2017-01-01T00:00:37"], "tai")[0] == t
    assert iso_to_tai_ns(["2017-01-01T00:00:18"], "gps")[0] == t
    assert iso_to_tai_ns(["2017-01-01T00:01:09.184"], "tt")[0] == t
    assert tai_ns_to_iso([t], "tt")[0] == "2017-01-01T00:01:09.184"
    assert TT_MINUS_TAI_S == 32.184 and TAI_MINUS_GPS_S == 19
    for scale, shift_s in (("tai", 0.0), ("gps", -19.0), ("tt", 32.184)):
        assert tai_ns_to_seconds([t], scale)[0] == UNIX_2017_S + 37 + shift_s


# ------------------------------------------------------------------------------ ISO details


def test_accepted_spellings_of_one_instant():
    spellings = ["2017-01-01T00:00:00Z", "2017-01-01T00:00:00", "2017-01-01 00:00:00+00:00",
                 "2017-01-01t00:00:00z", "2017-01-01T01:00:00+01:00", "2016-12-31T19:00:00-05:00",
                 "2017-01-01T05:30:00+0530", "2017-01-01T02:00:00.000000000+02", "2017-01-01T00:00:00,0Z"]
    t = iso_to_tai_ns(spellings)
    assert (t == (UNIX_2017_S + 37) * NS_PER_S).all()
    assert list(tai_ns_to_iso(iso_to_tai_ns(["2017-01-01T00:00:00.123456789Z"]))) == ["2017-01-01T00:00:00.123456789Z"]


def test_fraction_digits_are_the_fewest_exact_for_the_array():
    base = iso_to_tai_ns(["2020-02-29T12:34:56Z"])[0]
    assert tai_ns_to_iso([base])[0] == "2020-02-29T12:34:56Z"
    assert tai_ns_to_iso([base, base + 5 * 10**8])[1] == "2020-02-29T12:34:56.500Z"
    assert list(tai_ns_to_iso([base, base + 1_000])) == ["2020-02-29T12:34:56.000000Z", "2020-02-29T12:34:56.000001Z"]
    assert tai_ns_to_iso([base + 1])[0] == "2020-02-29T12:34:56.000000001Z"


def test_shapes_and_input_types():
    s = np.array([["2017-01-01T00:00:00Z", "2017-01-01T00:00:01Z"]] * 3)
    t = iso_to_tai_ns(s)
    assert t.shape == (3, 2) and tai_ns_to_iso(t).shape == (3, 2)
    assert iso_to_tai_ns("2017-01-01T00:00:00Z").shape == ()
    assert iso_to_tai_ns(pd.Series(["2017-01-01T00:00:00Z"], dtype="string"))[0] == t[0, 0]
    assert iso_to_tai_ns([]).shape == (0,) and tai_ns_to_iso(np.array([], dtype=np.int64)).shape == (0,)
    for scale in SCALES:
        assert tai_ns_to_seconds(t, scale).shape == (3, 2)
        assert tai_ns_to_jd(t, scale)[1].shape == (3, 2)
    assert epoch_ns_to_tai_ns(np.array(["2017-01-01T00:00:00"], "datetime64[ns]"), "utc")[0] == t[0, 0]


def test_bad_iso_rows_are_all_reported():
    values = ["2017-01-01T00:00:00Z", "", "garbage", float("nan"), None, "2016-12-31T23:59:61",
              "1971-12-31T23:59:59Z", "2017-02-29T00:00:00Z", "2017-01-01T00:00:00.1234567890Z",
              "2017-01-01T00:00:00+24:00", "2017-01-01", "2017-06-30T23:59:60Z", "2017-01-01T00:00:00é"]
    with pytest.raises(TimeValueError, match=r"row 1: empty time; row 2: 'garbage' is not an ISO 8601 time; "
                       r"row 3: NaN time") as err:
        iso_to_tai_ns(values)
    rows = dict(err.value.rows)
    assert sorted(rows) == list(range(1, len(values)))
    assert rows[4] == "missing time (None)"
    assert rows[5].startswith("'2016-12-31T23:59:61' is not an ISO 8601 time")
    assert "before 1972-01-01 UTC" in rows[6]
    assert "day 29 out of range 1-28" in rows[7]
    assert "more than 9 fractional digits" in rows[8]
    assert "zone hour 24" in rows[9]
    assert rows[10] == "'2017-01-01' is not an ISO 8601 time"
    assert rows[11] == "23:59:60 on 2017-06-30 is not a leap second"
    assert "Expected ISO 8601" in str(err.value) and "and 7 more" in str(err.value)


def test_second_60_is_utc_only_and_first_100_rows_kept():
    with pytest.raises(TimeValueError, match="scale tai has no leap seconds"):
        iso_to_tai_ns(["2016-12-31T23:59:60"], "tai")
    with pytest.raises(TimeValueError) as err:
        iso_to_tai_ns(["x"] * 250)
    assert len(err.value.rows) == 100 and err.value.rows[-1][0] == 99
    assert str(err.value).startswith("250 of 250 time values invalid")


def test_bad_numbers_and_arguments():
    with pytest.raises(TimeValueError, match="row 2: NaN time") as err:
        seconds_to_tai_ns(np.array([0.0, 1.0, np.nan, np.inf]), "tai")
    assert [r for r, _ in err.value.rows] == [2, 3]
    with pytest.raises(TimeValueError, match="row 0: .*before 1972-01-01 UTC"):
        seconds_to_tai_ns(np.array([0.0]), "utc")
    with pytest.raises(TimeValueError, match="row 1: NaT time"):
        epoch_ns_to_tai_ns(np.array(["2017-01-01", "NaT"], "datetime64[ns]"), "utc")
    with pytest.raises(TimeValueError, match="row 0: tai_ns 0 is before 1972-01-01 UTC"):
        tai_ns_to_iso(np.array([0]), "utc")
    with pytest.raises(TimeValueError, match="unknown time scale 'ut1'"):
        tai_ns_to_seconds(np.array([0]), "ut1")
    with pytest.raises(TimeValueError, match="integer nanoseconds"):
        tai_ns_to_iso(np.array([1.5]))
    with pytest.raises(TimeValueError, match="row 0: NaN time"):
        tai_ns_from_jd(np.array([np.nan]), np.array([0.0]), "tt")
    with pytest.raises(TimeValueError, match="dut1_s nan is not finite"):
        tai_ns_to_ut1_jd(np.array([TAI_1972_NS]), np.nan)
    assert tai_ns_to_iso(np.array([0]), "tai")[0] == "1970-01-01T00:00:00"  # other scales: any date


# --------------------------------------------------------------------------- round trips


tai_instants = st.integers(TAI_1972_NS, TAI_2036_NS)
near_leap = st.builds(lambda k, d: (IERS_STARTS_S[k] + IERS_TAI_MINUS_UTC[k][1]) * NS_PER_S + d,
                      st.integers(1, len(IERS_STARTS_S) - 1), st.integers(-3 * NS_PER_S, 3 * NS_PER_S))
instant_lists = st.lists(st.one_of(tai_instants, near_leap), min_size=1, max_size=40)


@settings(max_examples=150, deadline=None)
@given(instant_lists, st.sampled_from(SCALES))
def test_iso_round_trip(instants, scale):
    t = np.array(instants, dtype=np.int64)
    iso = tai_ns_to_iso(t, scale)
    np.testing.assert_array_equal(iso_to_tai_ns(iso, scale), t)
    assert list(tai_ns_to_iso(iso_to_tai_ns(iso, scale), scale)) == list(iso)


@settings(max_examples=150, deadline=None)
@given(instant_lists, st.sampled_from(SCALES))
def test_epoch_ns_and_jd_round_trips(instants, scale):
    t = np.array(instants, dtype=np.int64)
    np.testing.assert_array_equal(tai_ns_from_jd(*tai_ns_to_jd(t, scale), scale), t)
    if scale != "utc":  # the POSIX count cannot hold a leap second
        np.testing.assert_array_equal(epoch_ns_to_tai_ns(tai_ns_to_epoch_ns(t, scale), scale), t)
    order = np.sort(t)
    assert np.all(np.diff(tai_ns_to_seconds(order, scale)) >= 0)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats(63_072_000.0, 2_082_758_400.0), min_size=1, max_size=40), st.sampled_from(SCALES))
def test_seconds_round_trip(seconds, scale):
    s = np.array(seconds)
    # The float spacing here is >= 7.5 ns, so the nearest nanosecond brings back the same float.
    np.testing.assert_array_equal(tai_ns_to_seconds(seconds_to_tai_ns(s, scale, resolution_ns=1), scale), s)
    # The default microsecond rounding moves a value by at most 0.5 us (plus the float's spacing).
    np.testing.assert_allclose(tai_ns_to_seconds(seconds_to_tai_ns(s, scale), scale), s, rtol=0, atol=5.3e-7)


def test_float_tenths_read_back_exactly():
    s = 1.7e9 + 0.1 * np.arange(100_000)
    t = seconds_to_tai_ns(s, "tai")
    np.testing.assert_array_equal(np.diff(t), 100_000_000)
    with pytest.raises(TimeValueError, match="resolution_ns"):
        seconds_to_tai_ns(s, "tai", resolution_ns=7)


@settings(max_examples=150, deadline=None)
@given(st.datetimes(dt.datetime(1972, 1, 1), dt.datetime(2035, 12, 31, 23, 59, 59, 999999)))
def test_parse_matches_iers_table(when):
    posix_us = (when - dt.datetime(1970, 1, 1)) // dt.timedelta(microseconds=1)
    expected = posix_us * 1000 + iers_tai_minus_utc_s(posix_us / 1e6) * NS_PER_S
    assert iso_to_tai_ns([when.isoformat(timespec="microseconds") + "Z"])[0] == expected
    assert epoch_ns_to_tai_ns(np.array([posix_us * 1000]), "utc")[0] == expected


# ------------------------------------------------------------------------------- large input


def test_one_million_strings_across_a_leap_second():
    n, step_ns = 1_000_000, 1_000_000  # 1 ms steps from 23:50:00 UTC: the leap second is rows 600000-600999
    readings = np.datetime64("2016-12-31T23:50:00", "ns") + np.arange(n) * np.timedelta64(step_ns, "ns")
    readings[600_000:] -= np.timedelta64(1, "s")  # UTC readings: 23:59:60.xxx repeats no POSIX second
    iso = np.datetime_as_string(readings, unit="ms", timezone="UTC").astype(object)
    leap = slice(600_000, 601_000)
    iso[leap] = [s.replace("23:59:59.", "23:59:60.") for s in iso[leap]]
    assert iso[599_999] == "2016-12-31T23:59:59.999Z" and iso[600_000] == "2016-12-31T23:59:60.000Z"
    assert iso[601_000] == "2017-01-01T00:00:00.000Z"
    expected = (int(np.datetime64("2016-12-31T23:50:00", "s").astype(np.int64)) + 36) * NS_PER_S + np.arange(
        n, dtype=np.int64) * step_ns
    np.testing.assert_array_equal(iso_to_tai_ns(iso), expected)
    np.testing.assert_array_equal(tai_ns_to_iso(expected), iso)


@pytest.mark.parametrize("scale", ["utc", "tai", "gps", "tt"])
def test_long_series_text_from_tables_is_the_text_of_each_value(scale, monkeypatch):
    """Long series gather "YYYY-MM-DD" per day and "hh:mm:ss" per second of the day from tables: the same codes as
    computed value by value, across the 2016-12-31 leap second (23:59:60), at ms steps and at uneven steps over
    days; as bytes (uint8) too. The text itself is checked against erfa for a few of the values."""
    from processing.time import timescales as tsm

    leap = int(tsm.iso_to_tai_ns(["2016-12-31T23:59:00Z"])[0])
    series = [leap + np.arange(120_000, dtype=np.int64) * 10**6,
              leap - 3 * 86_400 * 10**9 + np.arange(30_000, dtype=np.int64) * 123_456_789]
    for t in series:
        assert t.size >= tsm.TABLE_MIN_ROWS
        gathered = tsm.tai_ns_to_iso_codes(t, scale)
        with monkeypatch.context() as m:
            m.setattr(tsm, "TABLE_MIN_ROWS", 10**12)  # every value on its own
            direct = tsm.tai_ns_to_iso_codes(t, scale)
        np.testing.assert_array_equal(gathered, direct)
        np.testing.assert_array_equal(tsm.tai_ns_to_iso_codes(t, scale, dtype=np.uint8), direct.astype(np.uint8))
    if scale == "utc":
        text = tsm.tai_ns_to_iso(series[0][59_000:61_000:500])
        assert list(text) == ["2016-12-31T23:59:59.000Z", "2016-12-31T23:59:59.500Z", "2016-12-31T23:59:60.000Z",
                              "2016-12-31T23:59:60.500Z"]
        t = series[1][::7_000]
        d1, d2 = erfa.taiutc(*erfa.dtf2d("TAI", *_tai_fields(t)))
        y, mo, d, hmsf = erfa.d2dtf("UTC", 6, d1, d2)  # these values have microseconds
        expected = [f"{a:04d}-{b:02d}-{c:02d}T{h[0]:02d}:{h[1]:02d}:{h[2]:02d}.{h[3]:06d}Z"
                    for a, b, c, h in zip(y, mo, d, hmsf, strict=True)]
        assert list(tsm.tai_ns_to_iso(t)) == expected


def _tai_fields(t):
    """TAI calendar fields of TAI ns values (1970-01-01T00:00:00 TAI epoch), for erfa.dtf2d."""
    days, ns = np.divmod(np.asarray(t, dtype=np.int64), 86_400 * 10**9)
    date = np.datetime64("1970-01-01") + days.astype("timedelta64[D]")
    ymd = pd.DatetimeIndex(date)
    sec = ns / 1e9
    return (ymd.year.to_numpy(), ymd.month.to_numpy(), ymd.day.to_numpy(), (sec // 3600).astype(int),
            ((sec % 3600) // 60).astype(int), sec % 60)
