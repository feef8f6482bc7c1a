"""The machine a benchmark ran on, recorded in every benchmark's JSON."""
from __future__ import annotations

import os
import platform
import sys

import numba
import numpy as np


def machine() -> dict:
    """Where the benchmark ran."""
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as handle:
            cpu = next(line.split(":", 1)[1].strip() for line in handle if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "numba_threads": numba.get_num_threads(),
            "python": sys.version.split()[0], "numpy": np.__version__, "numba": numba.__version__,
            "platform": platform.platform()}
