"""Partitioned processing inside a job: split a long window by time, run the parts in parallel, merge.

For algorithms whose work splits by time (screening, per-window fits, spectra of segments), a job
type's ``run`` cuts its inputs with :func:`time_partitions` / :func:`split_columns` and calls
:func:`map_partitions`, then merges the results itself. Where the parts run:

- on a Dask worker (``ATTITUDE_EXECUTOR=dask``): as tasks of the same cluster (BATCHES_PER_THREAD per
  worker thread, or ``max_workers``, each a run of consecutive parts), submitted from the job
  with ``distributed.worker_client`` (the job's thread secedes while it waits, so a cluster of
  single-threaded workers cannot deadlock);
- elsewhere (local executor, tests): in a thread pool of the job's worker process (numpy releases
  the GIL in its heavy loops), or in order when there is one part, or one thread to spare (inside a branch of
  :func:`map_concurrent`, which has as many threads as the machine has cores already).

``func`` must be a module-level function (Dask pickles it by reference), pure and deterministic, so
both paths give the same results; the results come back in the order of ``parts``.

:func:`map_concurrent` runs a few long, unequal pieces of one job side by side (the independent branches of
the ``reconstruction`` pipeline): each piece its own thread here, or its own task on a Dask cluster, with the
job's own thread watching for cancellation while they run.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from app.jobs.allocator import reuse_large_blocks
from processing.tasks import Progress, no_progress
from processing.units import NS_PER_S

T = TypeVar("T")
R = TypeVar("R")



def time_partitions(start_tai_ns: int, end_tai_ns: int, partition_s: float,
                    overlap_s: float = 0.0) -> list[tuple[int, int]]:
    """Cut [start, end] into consecutive parts of ``partition_s`` (the last one shorter), each widened by
    ``overlap_s`` on both sides (clipped to the window) for algorithms that need context at the edges.

    Returns (lo, hi) TAI ns pairs; a sample belongs to a part when lo <= t < hi (the last part includes end).
    """
    if partition_s <= 0:
        raise ValueError(f"partition_s must be positive, got {partition_s}")
    if end_tai_ns < start_tai_ns:
        raise ValueError(f"end ({end_tai_ns}) is before start ({start_tai_ns})")
    step = int(round(partition_s * NS_PER_S))
    pad = int(round(overlap_s * NS_PER_S))
    edges = list(range(start_tai_ns, end_tai_ns, step)) or [start_tai_ns]
    parts = []
    for i, lo in enumerate(edges):
        hi = end_tai_ns + 1 if i == len(edges) - 1 else lo + step
        parts.append((max(start_tai_ns, lo - pad), min(end_tai_ns + 1, hi + pad)))
    return parts


def split_columns(columns: Mapping[str, NDArray[Any]], parts: Sequence[tuple[int, int]],
                  time_column: str = "time_tai_ns") -> list[dict[str, NDArray[Any]]]:
    """The rows of ``columns`` in each part (lo <= t < hi), as views or copies of the arrays."""
    t = np.asarray(columns[time_column])
    out = []
    for lo, hi in parts:
        mask = (t >= lo) & (t < hi)
        out.append({k: np.asarray(v)[mask] for k, v in columns.items()})
    return out


def _dask_client_available() -> bool:
    if "distributed" not in sys.modules:
        return False  # no Dask worker runs this (a worker has it imported); importing it costs ~1.7 s of CPU
    try:
        from distributed import get_worker
    except ImportError:
        return False
    try:
        get_worker()
    except ValueError:
        return False
    return True


def _cluster_threads() -> int:
    """Worker threads of the cluster this task runs on."""
    from distributed import get_client

    return sum(get_client().nthreads().values())


BATCHES_PER_THREAD = 2
"""On Dask, the parts go in this many tasks per worker thread (consecutive runs of parts; some slack for
uneven parts)."""


def _batches(parts: list[T], k: int) -> list[list[T]]:
    """``parts`` cut into ``k`` consecutive runs of nearly equal length (in order)."""
    edges = np.linspace(0, len(parts), k + 1).round().astype(int)
    return [parts[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def _run_batch(func: Callable[[T], R], batch: Sequence[T]) -> list[R]:
    reuse_large_blocks()
    return [func(p) for p in batch]


def _run_part(func: Callable[[T, Progress], R], part: T, progress: Progress) -> R:
    reuse_large_blocks()
    return func(part, progress)


def map_partitions(func: Callable[[T], R], parts: Sequence[T], *, progress: Progress = no_progress,
                   stage: str = "partitions", max_workers: int | None = None) -> list[R]:
    """``[func(p) for p in parts]``, in parallel where the job runs (see the module docstring)."""
    n = len(parts)
    if n == 0:
        return []
    if n > 1 and _dask_client_available():
        from distributed import as_completed, worker_client

        with worker_client(separate_thread=True) as client:
            # a few tasks per worker thread, each a run of consecutive parts (small parts cost more to schedule
            # than to compute), their data sent to the workers directly rather than inside the task graph
            threads = sum(client.nthreads().values()) or 1
            batches = _batches(list(parts), min(n, max_workers or BATCHES_PER_THREAD * threads))
            futures = client.map(_run_batch, [func] * len(batches), client.scatter(batches, hash=False), pure=False)
            for done, _ in enumerate(as_completed(futures), start=1):
                progress(done / len(batches), f"{stage} {done}/{len(batches)}")
            return [r for batch in client.gather(futures) for r in batch]
    workers = max_workers or min(n, _threads_here())
    if workers == 1:
        results = []
        for i, p in enumerate(parts):
            results.append(func(p))
            progress((i + 1) / n, f"{stage} {i + 1}/{n}")
        return results
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="partition") as pool:
        futures_local = [pool.submit(func, p) for p in parts]
        out = []
        for i, f in enumerate(futures_local):
            out.append(f.result())
            progress((i + 1) / n, f"{stage} {i + 1}/{n}")
        return out


_branch = threading.local()


def _threads_here() -> int:
    """Threads a map_partitions may use here: the machine's cores, or a branch's share of them inside
    :func:`map_concurrent` (two branches on two cores each run their parts in order, not four threads on two)."""
    return int(getattr(_branch, "threads", 0)) or (os.cpu_count() or 1)


def _in_branch(func: Callable[[T, Progress], R], part: T, progress: Progress, threads: int) -> R:
    _branch.threads = threads
    try:
        return func(part, progress)
    finally:
        _branch.threads = 0


POLL_S = 0.5
"""How often :func:`map_concurrent` calls its ``poll`` while the pieces run (seconds)."""


def map_concurrent(func: Callable[[T, Progress], R], parts: Sequence[T], progresses: Sequence[Progress], *,
                   poll: Callable[[list[int]], None] = lambda finished: None) -> list[R]:
    """``[func(p, progress) for p, progress in zip(parts, progresses)]``, every part at the same time.

    Here: a thread per part, each given its own progress callback. On a Dask cluster of one worker thread: in
    order, in this task (side by side would only take turns, and move the data). On a larger one: a task per part on the
    same cluster (each part and its data on a worker of its own while there are workers), each given
    :func:`no_progress`, since a callback that writes to the job's database does not travel: the calling
    thread reports for them instead, ``progress(0.0, "running on a Dask worker")`` at the start and
    ``progress(1.0, "done on a Dask worker")`` as each finishes. Either
    way the calling thread calls ``poll(indices of the parts finished)`` every :data:`POLL_S` s while it waits, so a
    ``poll`` that raises (a cancelled job) stops the wait: the remaining Dask tasks are cancelled, and
    threads, which cannot be stopped, are waited for (their own progress callbacks raise the same way).
    The first exception of a part, in the order of ``parts``, is raised once all have ended; otherwise the
    results come back in the order of ``parts``. ``func`` is a module-level function, as for
    :func:`map_partitions`."""
    if len(progresses) != len(parts):
        raise ValueError(f"{len(parts)} parts but {len(progresses)} progress callbacks")
    if not parts:
        return []
    if len(parts) == 1:
        return [func(parts[0], progresses[0])]
    if _dask_client_available() and _cluster_threads() < 2:
        # one worker thread: the tasks would only take turns with this one, and pay for moving the parts
        # (measured: a spacecraft-day's reconstruction 25-28 s side by side against 16-20 s in order)
        return [func(p, progress) for p, progress in zip(parts, progresses, strict=True)]
    if _dask_client_available():
        from distributed import wait as dask_wait
        from distributed import worker_client

        with worker_client(separate_thread=True) as client:
            # each part on a worker of its own while there are workers to spare (the scheduler would otherwise
            # queue them where their data are; allow_other_workers keeps a lost worker from stranding one)
            workers = sorted(client.nthreads())
            futures = []
            for i, part in enumerate(parts):
                where = [workers[i % len(workers)]] if workers else None
                data = client.scatter([part], workers=where, hash=False)[0]  # a list: a dict part is no mapping
                futures.append(client.submit(_run_part, func, data, no_progress, pure=False, workers=where,
                                             allow_other_workers=True))
            reported: set[int] = set()
            try:
                for progress in progresses:
                    progress(0.0, "running on a Dask worker")
                while True:
                    finished = [i for i, f in enumerate(futures) if f.done()]
                    for i in sorted(set(finished) - reported):
                        progresses[i](1.0, "done on a Dask worker")
                        reported.add(i)
                    poll(finished)
                    if len(finished) == len(futures):
                        break
                    try:
                        dask_wait(futures, timeout=POLL_S, return_when="FIRST_COMPLETED")
                    except TimeoutError:
                        pass
            except BaseException:
                client.cancel(futures)
                raise
            return list(client.gather(futures))
    with ThreadPoolExecutor(max_workers=len(parts), thread_name_prefix="concurrent") as pool:
        share = max(1, (os.cpu_count() or 1) // len(parts))
        local = [pool.submit(_in_branch, func, p, prog, share) for p, prog in zip(parts, progresses, strict=True)]
        pending = set(local)
        while pending:
            poll([i for i, f in enumerate(local) if f not in pending])
            _, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
        poll(list(range(len(local))))
    return [f.result() for f in local]
