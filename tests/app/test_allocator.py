"""app.jobs.allocator: in a process started as Dask's nanny starts workers (MALLOC_TRIM_THRESHOLD_ set), large
temporaries are mapped afresh on every allocation until reuse_large_blocks() runs; afterwards they are reused."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

PROBE = r"""
import json, resource
import numpy as np
from app.jobs.allocator import reuse_large_blocks

def faults(rounds=30):
    # a day of 10 Hz samples as doubles (6.9 MB), written and freed again and again, as a job's temporaries are
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(rounds):
        a = np.ones(864_000)
        del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

faults(2)
before10, before30 = faults(10), faults(30)
took = reuse_large_blocks()
again = reuse_large_blocks()
faults(1)  # the heap grows once to hold the block (its pages may come as 4 KiB or huge pages: not counted)
print(json.dumps({"before10": before10, "before30": before30, "took": took, "again": again, "after": faults()}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_large_temporaries_are_reused_once_the_thresholds_are_set() -> None:
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536")  # what distributed.nanny.pre-spawn-environ sets
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=120,
                         check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["took"] and r["again"]
    # before: every round maps its block afresh and faults its pages in, so the count grows with the rounds
    # (how many faults a round costs depends on the kernel's page sizes, so only the proportion is asserted)
    per_round = r["before30"] / 30
    assert per_round > 50
    assert 2.5 * r["before10"] < r["before30"] < 3.5 * r["before10"]
    # after: the block stays in the heap and is reused; 30 rounds cost less than one fresh round did
    assert r["after"] < per_round
