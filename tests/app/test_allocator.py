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
first = faults()
took = reuse_large_blocks()
again = reuse_large_blocks()
print(json.dumps({"before": first, "took": took, "again": again, "after": faults()}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_large_temporaries_are_reused_once_the_thresholds_are_set() -> None:
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536")  # what distributed.nanny.pre-spawn-environ sets
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=120,
                         check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["took"] and r["again"]
    per_round = r["before"] / 30  # every round maps its block afresh and faults its pages in
    assert per_round > 100
    assert r["after"] < 2 * per_round  # the block is reused: its pages fault in once, in 30 rounds
