"""The stamp every benchmark prints above its table: commit, date, machine."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def stamp() -> str:
    """``commit abc1234, 2026-12-02, host (x86_64, 2 cores)``."""
    # --dirty: a result of code not yet committed says so
    commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    return (f"commit {commit}, {datetime.date.today()}, {platform.node()} "
            f"({platform.machine()}, {os.cpu_count()} cores)")
