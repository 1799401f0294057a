"""The machine a benchmark ran on, for the results files of ``make bench``.

Its own module so that every benchmark (:mod:`planner.bench.theta`, :mod:`planner.bench.courses`,
:mod:`planner.bench.physics`) uses it without importing another benchmark.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["machine_info"]


def machine_info() -> dict[str, Any]:
    """The machine a benchmark ran on: cores, CPU, versions, git commit, date and load."""
    import casadi
    import scipy

    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            cwd=Path(__file__).resolve().parent,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return {
        "nproc": os.cpu_count(),
        "cpu": cpu,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "casadi": casadi.__version__,
        "scipy": scipy.__version__,
        "git_commit": commit,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "load_average_1_5_15_at_start": [round(v, 2) for v in os.getloadavg()],
    }
