"""Benchmark: dataset throughput (scenes per minute: render + detect + solve + write).

    python bench/dataset.py [--n 6] [--workers 2] [--variants llvm scalar] [--spp N]

Each variant makes a fresh dataset of N full-size scenes from the default spec in a
temporary folder (the calibration made beforehand, as after a first run) and reports
scenes per minute of wall time (the spec's camera models calibrated beforehand, by a
one-scene dataset, as after a user's first run).
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=["llvm", "scalar"])
    ap.add_argument("--spp", type=int)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:  # calibrates the spec's camera models
        subprocess.run([sys.executable, "-m", "mirrorsim", "dataset", "--n", "1", "--seed",
                        "0", "--out", f"{tmp}/ds", "--quiet"], cwd=ROOT, check=True,
                       capture_output=True)
    print(f"dataset throughput, {a.n} scenes of 1920×1088, {a.workers} workers "
          f"({platform.machine()}, Python {platform.python_version()})\n")
    print("| variant | wall (s) | scenes/min |\n|---|---|---|")
    for v in a.variants:
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [sys.executable, "-m", "mirrorsim", "dataset", "--n", str(a.n), "--seed",
                   "0", "--out", f"{tmp}/ds", "--workers", str(a.workers), "--variant", v,
                   "--quiet"] + (["--spp", str(a.spp)] if a.spp else [])
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if proc.returncode:
                print(f"| {v} | failed: {proc.stderr.strip()[:80]} | |")
                continue
            print(f"| {v} | {wall:.1f} | {a.n / wall * 60:.1f} |")


if __name__ == "__main__":
    main()
