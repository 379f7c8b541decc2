"""Write the bytecode of every installed module the service and its tests import (``make install-dev``).

uv installs packages without their ``.pyc`` files, and where ``PYTHONDONTWRITEBYTECODE`` is set (as on the CI
machine) no process ever writes them: every process of the test suite - the job worker processes, the servers
started and killed by the crash tests, the Dask workers, the CLI runs - then compiles numpy, scipy, pandas,
matplotlib, distributed, ... afresh, ~3 s of CPU each. This imports what those processes import, then compiles
the source of each loaded module under the environment's site-packages whose cached bytecode is missing
(``compileall``, in parallel). Measured: the crash-safety and CLI tests 30.9 -> 24.2 s for ~11 s spent here.

Run: ``.venv/bin/python tools/compile_imports.py`` (idempotent; prints how many files it compiled).
"""

from __future__ import annotations

import compileall
import importlib
import importlib.util
import sys
import sysconfig
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

MODULES = ("app.main", "app.cli", "app.jobs.worker", "app.jobs.dask_executor", "app.jobs.registry",
           "app.reports.job_report", "distributed", "matplotlib.pyplot", "pytest", "hypothesis", "httpx")
"""What the suite's processes import: the service, its job types (through the registry), the Dask side, the
reports' plotting, and the test tools."""


def _missing_bytecode(path: str) -> bool:
    return not Path(importlib.util.cache_from_source(path)).exists()


def _compile(path: str) -> bool:
    return bool(compileall.compile_file(path, quiet=2))


def main() -> None:
    for name in MODULES:
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        if name == "app.jobs.registry":
            module.registry()  # imports every job type
    site = Path(sysconfig.get_paths()["purelib"]).resolve()
    sources = [getattr(m, "__file__", None) for m in list(sys.modules.values())]
    files = sorted({str(Path(f).resolve()) for f in sources if isinstance(f, str) and f.endswith(".py")})
    todo = [f for f in files if Path(f).is_relative_to(site) and _missing_bytecode(f)]
    with ProcessPoolExecutor() as pool:
        done = sum(pool.map(_compile, todo, chunksize=64))
    print(f"compiled {done} of {len(todo)} installed modules without bytecode ({len(files)} imported)")


if __name__ == "__main__":
    main()
