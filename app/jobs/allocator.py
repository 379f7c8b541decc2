"""The C allocator's thresholds in a Dask worker process (issue 24: a job on Dask cost 1.5-2x its CPU).

Dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (``distributed.nanny.pre-spawn-environ``,
so that freed memory goes back to the system at once). Setting any of glibc's thresholds turns off its dynamic
mmap threshold, so every allocation above 128 KiB - every numpy array of more than 16,384 doubles - is then a
fresh ``mmap``, unmapped again when freed: each temporary of a long window pays its page faults and the zeroing
of its pages in the kernel. Measured on a spacecraft-day's reconstruction in one process
(``/usr/bin/time``, the stages in order): 17.5 s of CPU (4.2 s of it in the kernel) by default, 27.6 s
(12.6 s in the kernel) with that variable set.

:func:`reuse_large_blocks` sets the two thresholds to where glibc's dynamic rule ends up on a numpy workload:
blocks up to 32 MiB come from the heap and are reused, and the top of the heap is given back once more than
64 MiB of it are free, so a worker's memory still goes back to the system between jobs, in larger steps.
Every task this service submits to a Dask cluster calls it first (it is process-wide and idempotent). The
cluster itself is the operator's: a worker started with other settings keeps them until a task of ours runs.
Where the C library has no ``mallopt`` (not glibc), it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading

M_TRIM_THRESHOLD = -1  # glibc's <malloc.h>
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 32 * 2**20
"""Blocks at or above this size are mapped and unmapped on their own (glibc's largest dynamic threshold on 64-bit
systems, DEFAULT_MMAP_THRESHOLD_MAX)."""
TRIM_THRESHOLD_BYTES = 2 * MMAP_THRESHOLD_BYTES
"""Free memory at the top of the heap beyond this is given back to the system (glibc's dynamic rule: twice the
mmap threshold)."""

_lock = threading.Lock()
_done: bool | None = None


def reuse_large_blocks() -> bool:
    """Set the thresholds (see the module docstring) once in this process; True if the C library took them."""
    global _done
    with _lock:
        if _done is None:
            _done = _set_thresholds()
        return _done


def _set_thresholds() -> bool:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    # mallopt returns 1 on success; the mmap threshold first (glibc caps it at HEAP_MAX/2, above 32 MiB)
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
