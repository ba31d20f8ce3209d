"""Benchmark: dataset throughput (scenes per minute: draw + render + detect + solve + write).

    python benchmarks/dataset.py [--n 24] [--workers 1 2] [--variants llvm] [--spp N]
                            [--sampler independent|multijitter]

For each variant and worker count, a fresh dataset of N full-size scenes of the default
spec is made in a temporary folder, and the scenes per minute of wall time (the whole
`mirrorsim dataset` process) are reported.  The spec's camera models are calibrated
beforehand by a one-scene dataset, as after a user's first run.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--variants", nargs="+", default=["llvm"])
    ap.add_argument("--spp", type=int)
    ap.add_argument("--sampler")
    a = ap.parse_args()
    extra = (["--spp", str(a.spp)] if a.spp else []) + (
        ["--sampler", a.sampler] if a.sampler else [])
    with tempfile.TemporaryDirectory() as tmp:  # calibrates the spec's camera models
        subprocess.run([sys.executable, "-m", "mirrorsim", "dataset", "--n", "1", "--seed",
                        "0", "--out", f"{tmp}/ds", "--quiet", *extra], cwd=ROOT, check=True,
                       capture_output=True)
    print(f"dataset throughput, {a.n} scenes of 1920×1088 ({' '.join(extra) or 'defaults'}); "
          f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}\n")
    print("| variant | workers | wall (s) | scenes/min |\n|---|---|---|---|")
    for v in a.variants:
        for w in a.workers:
            with tempfile.TemporaryDirectory() as tmp:
                cmd = [sys.executable, "-m", "mirrorsim", "dataset", "--n", str(a.n), "--seed",
                       "0", "--out", f"{tmp}/ds", "--workers", str(w), "--variant", v,
                       "--quiet", *extra]
                t0 = time.perf_counter()
                proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
                wall = time.perf_counter() - t0
            if proc.returncode:
                print(f"| {v} | {w} | failed: {proc.stderr.strip()[-80:]} | |")
                continue
            print(f"| {v} | {w} | {wall:.1f} | {a.n / wall * 60:.1f} |", flush=True)


if __name__ == "__main__":
    main()
