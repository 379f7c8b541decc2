"""Screening (002 eqs. 15-17 and generic checks): the "Done when" statistics on the seed-002 scenario,
and the building blocks on hand-made cases."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from processing.formats.rinex_nav import parse_rinex_nav
from processing.frames.earth_orientation import gcrs_to_itrs_state
from processing.screening import criteria as scr
from processing.screening.flags import accepted_mask, filter_streams, flags_table
from processing.simulate.seed002 import simulate_seed002
from processing.spacecraft import MissingMountingError, Spacecraft
from tests.real_data import GNSS_NAV

NAV = GNSS_NAV / "brdc2800.15n"
SEEDS = (0, 1, 2)
CRITERIA = {"energy", "orbit_plane", "kinematic", "velocity", "field_magnitude", "panel_range", "panel_eclipse",
            "panel_sun_norm", "visibility_occulted", "quaternion_norm", "quaternion_jump", "spike", "stuck",
            "time_grid"}


@cache
def nav():
    return parse_rinex_nav(NAV.read_bytes()).columns


@cache
def screened(seed: int):
    sc = simulate_seed002(nav=nav(), seed=seed, duration_s=3000.0)
    return sc, scr.screen(sc.streams, Spacecraft.from_json(sc.config), nav=nav())


def test_done_when_recall_and_false_flags() -> None:
    """>= 99 % of the injected gross faults flagged, <= 1 % of the clean samples flagged (per stream and
    overall, three seeds), and every rejected sample names its criteria."""
    faults = flagged_faults = clean = flagged_clean = 0
    for seed in SEEDS:
        sc, res = screened(seed)
        for stream, n in res.n_rows.items():
            truth = sc.truth.faults[stream]
            rej = res.rejected(stream)
            assert rej.size == n == truth.size
            faults += int(truth.sum())
            flagged_faults += int((rej & truth).sum())
            clean += int((~truth).sum())
            flagged_clean += int((rej & ~truth).sum())
            assert (rej & ~truth).sum() <= 0.01 * (~truth).sum(), (seed, stream)
            reasons = res.reasons(stream)
            assert np.all((reasons != "") == rej)
            named = {x for r in reasons[rej] for x in r.split(";")}
            assert named <= CRITERIA
    assert faults > 200
    assert flagged_faults >= 0.99 * faults
    assert flagged_clean <= 0.01 * clean


def test_summary_and_flags_table() -> None:
    sc, res = screened(0)
    summary = res.summary()
    assert summary["gnss"]["energy"]["source"] == "002 eq. 15"
    assert summary["magnetometer"]["field_magnitude"]["threshold"] == pytest.approx(3 * (100 + 150))
    assert summary["panel_currents"]["panel_eclipse"]["source"] == "002 eq. 17"
    for per in summary.values():
        for d in per.values():
            assert set(d) == {"n_total", "n_applied", "n_rejected", "threshold", "unit", "source"}
    table = flags_table(res, sc.streams)
    assert len(table["time_tai_ns"]) == sum(res.n_rows.values())
    assert set(table["stream"]) == set(res.n_rows)
    pc = table["stream"] == "panel_currents"
    assert set(table["key"][pc]) == {str(k) for k in range(6)}
    # the runner's filter: rejected rows removed, everything else kept
    kept = filter_streams(sc.streams, table)
    for stream in res.n_rows:
        assert len(kept[stream]["time_tai_ns"]) == res.n_rows[stream] - res.rejected(stream).sum()
    mask = accepted_mask(table, "panel_currents", sc.streams["panel_currents"])
    np.testing.assert_array_equal(mask, ~res.rejected("panel_currents"))
    # a flags table of another stream or window leaves a stream untouched
    assert accepted_mask(table, "gyro", {"time_tai_ns": np.arange(3), "sensor": np.array(["g"] * 3)}).all()


def test_filter_matches_rejections_by_sensor_key_and_time_exactly() -> None:
    """The stored table's rejections, matched against a plain set of (stream, sensor, key, time): rows that share a
    rejected row's time but not its sensor or panel are kept; a shuffled table (as read back) gives the same."""
    rng = np.random.default_rng(11)
    n = 600
    t = np.repeat(np.arange(n // 6, dtype=np.int64) * 10**9, 6)  # six panels per time
    panels = {"time_tai_ns": t, "sensor": rng.choice(np.array(["A", "B"], dtype=object), n),
              "panel": np.tile(np.arange(6), n // 6), "current": rng.normal(size=n)}
    gyro = {"time_tai_ns": t[::6], "sensor": np.full(n // 6, "A", dtype=object), "wx": rng.normal(size=n // 6)}
    streams = {"panel_currents": panels, "gyro": gyro}
    rows = {k: [] for k in ("time_tai_ns", "stream", "sensor", "key", "accepted")}
    for name, cols in streams.items():
        keys = [str(p) for p in cols["panel"]] if "panel" in cols else [""] * len(cols["time_tai_ns"])
        for i, ti in enumerate(cols["time_tai_ns"]):
            rows["time_tai_ns"].append(int(ti))
            rows["stream"].append(name)
            rows["sensor"].append(str(cols["sensor"][i]))
            rows["key"].append(keys[i])
            rows["accepted"].append(bool(rng.random() > 0.1))
    table = {k: np.array(v, dtype=object if k in ("stream", "sensor", "key") else None) for k, v in rows.items()}
    refused = {(s, se, k, int(ti)) for s, se, k, ti, a in zip(table["stream"], table["sensor"], table["key"],
                                                               table["time_tai_ns"], table["accepted"], strict=True)
               if not a}
    order = rng.permutation(len(table["time_tai_ns"]))
    shuffled = {k: v[order] for k, v in table.items()}
    for flags in (table, shuffled):
        kept = filter_streams(streams, flags)
        for name, cols in streams.items():
            keys = [str(p) for p in cols["panel"]] if "panel" in cols else [""] * len(cols["time_tai_ns"])
            expected = np.array([(name, str(se), k, int(ti)) not in refused
                                 for se, k, ti in zip(cols["sensor"], keys, cols["time_tai_ns"], strict=True)])
            np.testing.assert_array_equal(accepted_mask(flags, name, cols), expected)
            np.testing.assert_array_equal(kept[name]["time_tai_ns"], cols["time_tai_ns"][expected])
    assert 0 < sum(1 for r in refused if r[0] == "panel_currents") < n  # both kinds of rows present


def test_j2_aware_energy_against_two_body() -> None:
    """With the model error of the J2 variant (300 m^2/s^2), the paper's two-body h flags a real (J2)
    orbit all round; the J2-aware h flags nothing. A reference orbit removes the need for a fit."""
    sc, _ = screened(0)
    tr = sc.truth
    clean = {"time_tai_ns": tr.time_tai_ns, "sensor": np.full(tr.time_tai_ns.size, "gnss", dtype=object),
             **{c: tr.r_E[:, i] for i, c in enumerate("xyz")}, **{c: tr.v_E[:, i] for i, c in enumerate(("vx", "vy",
                                                                                                       "vz"))}}
    p2 = scr.ScreeningParams(energy_model="two_body", energy_model_error_m2_s2=300.0)
    res2 = scr.screen({"gnss": clean}, Spacecraft(), p2)
    resj = scr.screen({"gnss": clean}, Spacecraft(), scr.ScreeningParams())
    energy2 = next(c for c in res2.criteria if c.name == "energy")
    energyj = next(c for c in resj.criteria if c.name == "energy")
    assert energy2.flagged.mean() > 0.3
    assert not energyj.flagged.any() and np.max(energyj.statistic) < 100.0
    # default two-body tolerance includes the J2 oscillation: nothing flagged either
    assert not next(c for c in scr.screen({"gnss": clean}, Spacecraft(),
                                          scr.ScreeningParams(energy_model="two_body")).criteria
                    if c.name == "energy").flagged.any()
    # reference orbit in ITRF and in GCRS: the statistic is the GNSS noise only
    ref_E = {"time_tai_ns": tr.time_tai_ns[::30], **{c: tr.r_E[::30, i] for i, c in enumerate("xyz")},
             **{c: tr.v_E[::30, i] for i, c in enumerate(("vx", "vy", "vz"))}}
    ref_I = {"time_tai_ns": tr.time_tai_ns[::30], **{c: tr.r_I[::30, i] for i, c in enumerate("xyz")},
             **{c: tr.v_I[::30, i] for i, c in enumerate(("vx", "vy", "vz"))}}
    for ref, frame in ((ref_E, "ITRF"), (ref_I, "GCRF")):
        res = scr.screen({"gnss": clean}, Spacecraft(), reference_orbit=ref, reference_frame=frame)
        stat = next(c for c in res.criteria if c.name == "energy").statistic
        assert np.nanmax(stat) < 60.0, frame


def test_energy_h_of_a_two_body_orbit_is_constant() -> None:
    from processing.orbits.two_body import circular_orbit_state
    from processing.units import MU_EARTH_M3_S2

    t = np.arange(0, 6000, 10.0)
    r_I, v_I = circular_orbit_state(t, 7.0e6, 1.7, 0.3, 0.1)
    r_E, v_E = gcrs_to_itrs_state(r_I, v_I, 1_443_000_000 * 10**9 + (t * 1e9).astype(np.int64))
    h = scr.energy_h(r_E, v_E, "two_body")
    np.testing.assert_allclose(h, -MU_EARTH_M3_S2 / 7.0e6, rtol=1e-6)
    dh = scr.energy_tolerance(r_E, v_E, 10.0, 0.1)
    assert dh[0] == pytest.approx(2 * (np.sqrt(MU_EARTH_M3_S2 / 7e6) * 0.1 + MU_EARTH_M3_S2 / 7e6**2 * 10.0), rel=1e-3)


def test_building_blocks() -> None:
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(500, 3)) * 0.1, axis=0) + rng.normal(size=(500, 3))
    x[100] += [20.0, 0.0, 0.0]
    dist, thr, flagged = scr.hampel(x, 5, 6.0)
    assert flagged[100] and flagged.sum() <= 2
    assert thr == pytest.approx(6.0 * 1.1, rel=0.25)  # robust sigma ~ 1.05 (median of neighbours adds ~8 %)
    v = np.arange(40.0)
    v[10:25] = 7.0
    st = scr.stuck(v, 10)
    assert st.sum() == 14 and not st[10] and st[11:25].all()
    assert not scr.stuck(v, 16).any()
    t = np.arange(20, dtype=np.int64) * 10**9
    t[5] += 4 * 10**8  # shifted sample: both intervals off the grid
    t[12:] += 3 * 10**8  # phase change after sample 11: one odd interval only, not flagged
    t = np.insert(t, 8, t[8])  # duplicate
    f, _, period = scr.time_grid(t, 0.25)
    assert period == 10**9 and np.flatnonzero(f).tolist() == [5, 9]
    assert scr.attribute_increments(np.array([False, True, True, False, False, True, False])).tolist() == [
        False, False, True, False, False, False, True, False]
    assert scr.attribute_increments(np.array([True, False])).tolist() == [True, False, False]
    # sun from a cube's currents: exact, including a sun along a face (one lit panel)
    normals = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    s = np.array([[0.6, -0.48, 0.64], [0.0, 1.0, 0.0]])
    cur = 1.2 * np.maximum(0.0, s @ normals.T)
    est, det = scr.sun_from_currents(cur, normals, np.full(6, 1.2), lit_threshold_a=0.03)
    np.testing.assert_allclose(est, s, atol=1e-8)
    assert det.all()


def test_star_tracker_jumps_against_gyro() -> None:
    """A quaternion jump inconsistent with the gyro is flagged; steady rotation is not."""
    from processing.attitude import rotations

    t = np.arange(0, 300, 1.0)
    w = np.array([0.01, -0.005, 0.002])
    q = rotations.rotvec_to_quat(t[:, None] * w)
    q[150] = rotations.quat_multiply(q[150], rotations.rotvec_to_quat([0.01, 0.0, 0.0]))
    st = {"time_tai_ns": (t * 1e9).astype(np.int64), "sensor": np.full(t.size, "st1", dtype=object),
          **{f"q{i}": q[:, i] for i in range(4)}}
    tg = np.arange(0, 300, 0.1)
    gyro = {"time_tai_ns": (tg * 1e9).astype(np.int64), "sensor": np.full(tg.size, "gyro", dtype=object),
            **{c: w[i] + 1e-7 * np.random.default_rng(i).normal(size=tg.size) for i, c in enumerate(("wx", "wy",
                                                                                                      "wz"))}}
    res = scr.screen({"star_tracker": st, "gyro": gyro},
                     Spacecraft.from_json({"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}}))
    jump = next(c for c in res.criteria if c.stream == "star_tracker" and c.name == "quaternion_jump")
    assert np.flatnonzero(jump.flagged).tolist() == [150]
    assert res.rejected("gyro").sum() == 0
    assert "no GNSS stream" in " ".join(res.notes)
    exact = dict(gyro, wx=np.full(tg.size, w[0]), wy=np.full(tg.size, w[1]), wz=np.full(tg.size, w[2]))
    stuck = scr.screen({"gyro": exact}, Spacecraft())  # a real gyro never repeats its noise exactly
    assert next(c for c in stuck.criteria if c.name == "stuck").flagged.sum() == tg.size - 1


@pytest.mark.parametrize("step", [10, 60])
def test_sparse_gnss_is_not_flagged(step: int) -> None:
    """GNSS every 10 s or 60 s: the kinematic and velocity tolerances grow with the orbit's jerk, so the
    clean (noisy) samples pass and gross position errors are still caught."""
    sc, _ = screened(0)
    clean = sc.truth.clean["gnss"]
    sel = slice(0, None, step)
    t = sc.truth.time_tai_ns[sel]
    r, v = clean["r_E"][sel].copy(), clean["v_E"][sel].copy()
    bad = np.arange(5, t.size - 5, 17)
    r[bad] += np.array([3000.0, -2000.0, 1000.0])
    g = {"time_tai_ns": t, "sensor": np.full(t.size, "gnss", dtype=object),
         **{c: r[:, i] for i, c in enumerate("xyz")}, **{c: v[:, i] for i, c in enumerate(("vx", "vy", "vz"))}}
    res = scr.screen({"gnss": g}, Spacecraft())
    rej = res.rejected("gnss")
    assert rej[bad].all()
    assert rej.sum() - bad.size <= max(1, 0.01 * t.size)


def test_star_tracker_against_gyro_needs_its_mounting() -> None:
    """The jump test against the gyro rotates the rates into the tracker frame: a tracker without a
    configured mounting is an error naming it (it used to get an identity mounting silently)."""
    t = np.arange(0, 20, 1.0)
    st = {"time_tai_ns": (t * 1e9).astype(np.int64), "sensor": np.full(t.size, "st2", dtype=object),
          "q0": np.ones(t.size), "q1": np.zeros(t.size), "q2": np.zeros(t.size), "q3": np.zeros(t.size)}
    gyro = {"time_tai_ns": (t * 1e9).astype(np.int64), "sensor": np.full(t.size, "gyro", dtype=object),
            "wx": np.zeros(t.size), "wy": np.zeros(t.size), "wz": np.zeros(t.size)}
    config = Spacecraft.from_json({"star_trackers": {"st1": {"q_BS": [1, 0, 0, 0]}}})
    with pytest.raises(MissingMountingError, match=r"star tracker 'st2' is not in the spacecraft configuration "
                                                   r"\(configured: st1\)"):
        scr.screen({"star_tracker": st, "gyro": gyro}, config)
    without_gyro = scr.screen({"star_tracker": st}, config)  # against max_rate_rad_s: no mounting needed
    assert without_gyro.n_rows == {"star_tracker": t.size}


def test_rolling_median_is_numpys_nanmedian_of_the_windows():
    """rolling_median sorts the short windows itself (numpy's nanmedian takes a slow masked route there): the
    same values, NaN for windows without a sample, even and odd counts, excluded rows and a left-out centre."""
    from numpy.lib.stride_tricks import sliding_window_view

    from processing.screening.tools import nanmedian_last_axis, rolling_median

    rng = np.random.default_rng(4)
    a = rng.normal(size=(3000, 3))
    a[rng.random(3000) < 0.2] = np.nan
    a[100:140] = np.nan  # windows with no sample at all
    for hw in (1, 4, 7):
        win = sliding_window_view(np.concatenate([np.full((hw, 3), np.nan), a, np.full((hw, 3), np.nan)]),
                                  2 * hw + 1, axis=0)
        with np.errstate(all="ignore"), pytest.warns(RuntimeWarning):
            expected = np.nanmedian(win, axis=-1)
        np.testing.assert_array_equal(nanmedian_last_axis(win), expected)
    exclude = rng.random(3000) < 0.1
    med = rolling_median(a, 3, exclude, leave_out_centre=True)
    b = np.where(exclude[:, None], np.nan, a)
    win = sliding_window_view(np.concatenate([np.full((3, 3), np.nan), b, np.full((3, 3), np.nan)]), 7, axis=0).copy()
    win[:, :, 3] = np.nan
    with pytest.warns(RuntimeWarning):
        np.testing.assert_array_equal(med, np.nanmedian(win, axis=-1))


def test_the_streams_give_the_same_result_on_any_mapper() -> None:
    """The streams are screened through the mapper (a cluster's workers in a job) in two passes, GNSS beside the
    streams that need no position, then those that need its track: run in reverse order on other threads, the
    criteria, notes and findings are those of the serial run, in its order."""
    from concurrent.futures import ThreadPoolExecutor

    sc, serial = screened(0)
    names: list[list[str]] = []

    def reversed_threads(func, parts):  # noqa: ANN001, ANN202
        names.append([p.name for p in parts])
        with ThreadPoolExecutor(2) as pool:
            return list(reversed(list(pool.map(func, list(reversed(parts))))))

    mapped = scr.screen(sc.streams, Spacecraft.from_json(sc.config), nav=nav(), mapper=reversed_threads)
    free = [s for s in sc.streams if s != "gnss" and s not in scr.NEEDS_TRACK]
    assert len(names) == 2 and names[0] == ["gnss", *free]
    assert set(names[1]) == scr.NEEDS_TRACK and not set(names[0]) & set(names[1])
    assert [(c.stream, c.name) for c in mapped.criteria] == [(c.stream, c.name) for c in serial.criteria]
    for a, b in zip(mapped.criteria, serial.criteria, strict=True):
        for field in ("flagged", "applied", "statistic"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert (mapped.n_rows, mapped.notes, mapped.findings) == (serial.n_rows, serial.notes, serial.findings)


def test_the_rolling_median_in_blocks_is_the_whole_one() -> None:
    """rolling_median works in blocks of rows (bounded memory): any block size gives the same medians."""
    from processing.screening.tools import rolling_median

    rng = np.random.default_rng(4)
    x = rng.normal(size=(1000, 3))
    x[rng.random(1000) < 0.05, 1] = np.nan
    exclude = rng.random(1000) < 0.1
    whole = rolling_median(x, 5, exclude, leave_out_centre=True, chunk_rows=10**6)
    for rows in (1, 7, 64, 999):
        np.testing.assert_array_equal(rolling_median(x, 5, exclude, leave_out_centre=True, chunk_rows=rows), whole)
    one_d = rolling_median(x[:, 0], 3, chunk_rows=10**6)
    np.testing.assert_array_equal(rolling_median(x[:, 0], 3, chunk_rows=13), one_d)
    neighbours = [*range(495, 500), *range(501, 506)]
    assert whole[500, 0] == np.median(x[neighbours, 0][~exclude[neighbours]])
