"""Benchmark: wall time of `mirrorsim evaluate` on a full-size scene (fresh render).

    python benchmarks/evaluate.py [--scene scenes/default.yaml] [--repeat 2] [--spp N]

Each run is a new process with an empty output folder, so the frame is rendered, not
reused; the calibration is made first (cached, as after a user's first run).  Prints
the best wall time and the time of a second call that reuses the render.
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


def run(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mirrorsim", *args], cwd=ROOT, check=True,
                   capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/default.yaml")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--spp", type=int)
    a = ap.parse_args()
    extra = ["--spp", str(a.spp)] if a.spp else []
    run(["calibrate", a.scene])
    fresh, reuse = [], []
    for _ in range(a.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            fresh.append(run(["evaluate", a.scene, "--out", tmp, "--quiet", *extra]))
            reuse.append(run(["evaluate", a.scene, "--out", tmp, "--quiet", *extra]))
    print(f"`mirrorsim evaluate {a.scene}` ({platform.machine()}, Python "
          f"{platform.python_version()}): fresh render {min(fresh):.2f} s wall (best of "
          f"{a.repeat}), reusing the render {min(reuse):.2f} s")


if __name__ == "__main__":
    main()
