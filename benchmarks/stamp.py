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
    commit = subprocess.run(["git", "describe", "--always"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    # a result of code not yet committed says so; the docs' prose and the results and
    # figures a `regenerate.py` run has written before this one are not code (nor the
    # README, whose quick-start block is the demo result, copied)
    changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                              ".", ":(exclude)docs/results", ":(exclude,glob)docs/*.md",
                              ":(exclude,glob)docs/*.png", ":(exclude)README.md"], cwd=ROOT,
                             capture_output=True, text=True).stdout.strip()
    commit += "-dirty" if changed else ""
    return (f"commit {commit}, {datetime.date.today()}, {platform.node()} "
            f"({platform.machine()}, {os.cpu_count()} cores)")
