"""app.jobs.plausibility.checked: the star-tracker-against-gyro check computed once per process for equal inputs
(star_tracker_accuracy and gyro_bias_fit in one reconstruction), recomputed when any input differs, bounded."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from app.jobs import plausibility
from app.jobs.types.gyro_bias_fit import JOB as GYRO_BIAS_FIT
from app.jobs.types.star_tracker_accuracy import JOB as STAR_TRACKER_ACCURACY
from processing.simulate.seed003 import Scenario003, simulate_seed003
from processing.spacecraft import Spacecraft
from processing.tasks import TaskInputs, no_progress

T0_NS = 1_900_000_000 * 1_000_000_000


@pytest.fixture(scope="module")
def sc() -> Scenario003:
    return simulate_seed003(start_tai_ns=T0_NS, duration_s=600.0, seed=3, gnss_period_s=600.0)


@pytest.fixture
def calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts the real checks run; the cache starts empty."""
    count: list[int] = []
    real = plausibility.check_star_tracker_gyro

    def counting(*args: Any, **kwargs: Any) -> Any:
        count.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(plausibility, "check_star_tracker_gyro", counting)
    monkeypatch.setattr(plausibility, "_cache", type(plausibility._cache)())
    return count


def _args(sc: Scenario003) -> tuple[Any, ...]:
    st, g = sc.streams["star_tracker"], sc.streams["gyro"]
    cfg = Spacecraft.from_json(sc.config)
    name = cfg.star_tracker_names[0]
    sel = np.asarray(st["sensor"]) == name
    q_IS = np.column_stack([np.asarray(st[c])[sel] for c in ("q0", "q1", "q2", "q3")])
    w_G = np.column_stack([np.asarray(g[c]) for c in ("wx", "wy", "wz")])
    return (np.asarray(st["time_tai_ns"])[sel], q_IS, cfg.star_tracker_mounting(name), np.asarray(g["time_tai_ns"]),
            w_G, cfg.gyro_mounting())


def test_equal_inputs_are_checked_once_and_each_caller_gets_its_own_copy(sc: Scenario003, calls: list[int]) -> None:
    args = _args(sc)
    first = plausibility.checked(*args, sensor="st1")
    second = plausibility.checked(*(np.array(a, copy=True) for a in args), sensor="st1")  # equal, not the same
    assert len(calls) == 1
    assert first.summary() == second.summary() and first is not second
    first.gyro_bias_G_rad_s[:] = np.nan  # a caller spoiling its copy spoils nobody else's
    assert np.all(np.isfinite(plausibility.checked(*args, sensor="st1").gyro_bias_G_rad_s))
    assert np.all(np.isfinite(second.gyro_bias_G_rad_s)) and len(calls) == 1


def test_any_different_input_is_checked_anew(sc: Scenario003, calls: list[int]) -> None:
    args = _args(sc)
    plausibility.checked(*args, sensor="st1")
    q = args[1].copy()
    q[5, 1] = np.nextafter(q[5, 1], 1.0)  # one bit of one quaternion
    plausibility.checked(args[0], q, *args[2:], sensor="st1")
    plausibility.checked(*args, sensor="st1", max_time_offset_s=0.5)
    plausibility.checked(*args, sensor="other name")
    assert len(calls) == 4
    for k in range(plausibility.CHECK_CACHE_SIZE + 2):
        plausibility.checked(*args, sensor="st1", max_time_offset_s=0.1 + 0.1 * k)
    assert len(plausibility._cache) == plausibility.CHECK_CACHE_SIZE


def test_a_pipeline_checks_once_for_both_stages(sc: Scenario003, calls: list[int]) -> None:
    """star_tracker_accuracy then gyro_bias_fit on the same window (as in reconstruction): one check, and the
    gyro fit's findings are those of a check of its own."""
    inputs = TaskInputs(streams=sc.streams, spacecraft=Spacecraft.from_json(sc.config), start_tai_ns=T0_NS,
                        end_tai_ns=T0_NS + 600 * 10**9)
    acc = STAR_TRACKER_ACCURACY.run(inputs, STAR_TRACKER_ACCURACY.params(), no_progress)
    fit = GYRO_BIAS_FIT.run(inputs, GYRO_BIAS_FIT.params(), no_progress)
    assert len(calls) == 1
    plausibility._cache.clear()
    alone = GYRO_BIAS_FIT.run(inputs, GYRO_BIAS_FIT.params(), no_progress)
    assert len(calls) == 2
    assert fit.summary == alone.summary
    assert acc.summary["plausibility"]["st1"]["checked"]


def test_concurrent_callers_of_one_check_wait_for_it(sc: Scenario003, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two threads asking for the same check while it runs (the branches of reconstruction side by side): it
    runs once, both get its result; an error of the check reaches both, and nothing is kept."""
    import threading
    import time
    from concurrent.futures import ThreadPoolExecutor

    started, release = threading.Event(), threading.Event()
    count: list[int] = []
    real = plausibility.check_star_tracker_gyro

    def slow(*args: Any, **kwargs: Any) -> Any:
        count.append(1)
        started.set()
        assert release.wait(30)
        if kwargs["sensor"] == "broken":
            raise plausibility.PlausibilityError("too few samples")
        return real(*args, **kwargs)

    monkeypatch.setattr(plausibility, "check_star_tracker_gyro", slow)
    monkeypatch.setattr(plausibility, "_cache", type(plausibility._cache)())
    args = _args(sc)
    for sensor in ("st1", "broken"):
        started.clear()
        release.clear()
        count.clear()
        with ThreadPoolExecutor(2) as pool:
            first = pool.submit(plausibility.checked, *args, sensor=sensor)
            assert started.wait(30)
            second = pool.submit(plausibility.checked, *args, sensor=sensor)
            time.sleep(0.3)  # the second caller is at its check by now (a digest of these arrays takes ~1 ms)
            release.set()
            if sensor == "broken":
                for f in (first, second):
                    with pytest.raises(plausibility.PlausibilityError, match="too few"):
                        f.result()
            else:
                assert first.result().summary() == second.result().summary()
                assert first.result() is not second.result()
        assert len(count) == 1
        assert not plausibility._running
    assert len(plausibility._cache) == 1
