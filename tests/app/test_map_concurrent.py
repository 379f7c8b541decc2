"""app.jobs.partitions.map_concurrent in the worker process: the parts at the same time, each with its own
progress callback, results in order, errors in order of the parts, and a poll that can stop the wait."""

from __future__ import annotations

import threading
import time

import pytest

from app.jobs import partitions
from app.jobs.partitions import map_concurrent


def _wait_for_all(part, progress):
    barrier, name = part
    progress(0.5, name)
    barrier.wait(timeout=10)  # returns only when every part is running at once
    return name, threading.get_ident()


def test_parts_run_at_once_each_with_its_progress_and_come_back_in_order():
    barrier = threading.Barrier(3)
    seen: dict[str, list[tuple[float, str]]] = {"a": [], "b": [], "c": []}
    polls: list[list[int]] = []
    out = map_concurrent(_wait_for_all, [(barrier, n) for n in "abc"],
                         [lambda f, s, _k=k: seen[_k].append((f, s)) for k in "abc"], poll=polls.append)
    assert [n for n, _ in out] == ["a", "b", "c"]
    assert len({ident for _, ident in out}) == 3
    assert seen == {k: [(0.5, k)] for k in "abc"}
    assert polls[-1] == [0, 1, 2] and all(sorted(p) == p for p in polls)


def _fail(part, progress):
    delay, message = part
    time.sleep(delay)
    if message:
        raise ValueError(message)
    return delay


def test_the_first_error_in_the_order_of_the_parts_is_raised_after_all_ended():
    ended = []
    with pytest.raises(ValueError, match="first"):
        map_concurrent(_fail, [(0.3, "first"), (0.0, "second"), (0.1, None)], [lambda f, s: None] * 3,
                       poll=ended.append)
    assert ended[-1] == [0, 1, 2]
    assert map_concurrent(_fail, [(0.0, None)], [lambda f, s: None]) == [0.0]
    assert map_concurrent(_fail, [], []) == []
    with pytest.raises(ValueError, match="2 parts but 1 progress"):
        map_concurrent(_fail, [(0.0, None)] * 2, [lambda f, s: None])


class Stop(Exception):
    pass


def test_a_poll_that_raises_ends_the_wait():
    release = threading.Event()

    def poll(finished: list[int]) -> None:
        if finished == [1]:  # the quick part is done, the slow one still runs: stop (a cancel)
            release.set()
            raise Stop()

    def slow_or_quick(part, progress):
        if part == "slow":
            assert release.wait(10)
        return part

    t0 = time.monotonic()
    with pytest.raises(Stop):
        map_concurrent(slow_or_quick, ["slow", "quick"], [lambda f, s: None] * 2, poll=poll)
    assert time.monotonic() - t0 < 5


def _thread_of_parts(part, progress):  # noqa: ANN001, ANN202 - a branch that splits its own work
    return partitions.map_partitions(_thread_name, [part, part, part])


def _thread_name(_part):  # noqa: ANN001, ANN202
    return threading.current_thread().name


@pytest.mark.parametrize("cores", [2, 4])
def test_a_branch_splits_its_parts_over_its_share_of_the_cores(cores, monkeypatch):
    """Two branches on two cores run their map_partitions in order in their own threads (not four threads on two
    cores); with four cores each branch has two threads for its parts. Outside a branch: every core."""
    monkeypatch.setattr(partitions.os, "cpu_count", lambda: cores)
    names = partitions.map_concurrent(_thread_of_parts, ["a", "b"], [lambda f, s: None] * 2)
    for branch in names:
        if cores == 2:
            assert len(set(branch)) == 1 and branch[0].startswith("concurrent")
        else:
            assert all(n.startswith("partition") for n in branch)
    assert all(n.startswith("partition") for n in partitions.map_partitions(_thread_name, [1, 2, 3]))
