"""Benchmark: the wall time of whole commands, as a user waits for them.

    python benchmarks/commands.py [--repeat 3]

Each command runs as its own process (start-up included), ``--repeat`` times, and the
median and the range are printed: ``mirrorsim --help``, ``check`` and ``evaluate`` of
the default scene with a fresh render each time (a new output folder; the kernel and
calibration caches as the user has them after a first run), and ``budget
scenes/bench/exp1.yaml`` (its frames fresh too).  Stamped with commit, date and machine.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
from stamp import stamp  # noqa: E402  (benchmarks/ is the script's own folder on sys.path)


def _wall(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mirrorsim", *argv], cwd=ROOT, check=True,
                   capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    print(f"{stamp()}\n")
    print("| command | median (s) | range (s) |\n|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        runs = {
            "mirrorsim --help": lambda _k: ["--help"],
            "mirrorsim check scenes/default.yaml": lambda _k: ["check", "scenes/default.yaml"],
            "mirrorsim evaluate scenes/default.yaml (a fresh render)":
                lambda k: ["evaluate", "scenes/default.yaml", "--quiet", "--out",
                           f"{tmp}/evaluate{k}"],
            "mirrorsim budget scenes/bench/exp1.yaml (fresh renders)":
                lambda k: ["budget", "scenes/bench/exp1.yaml", "--quiet", "--out",
                           f"{tmp}/budget{k}"],
        }
        # the kernel and calibration caches as a user has them after a first run of each
        for label in ("mirrorsim evaluate scenes/default.yaml (a fresh render)",
                      "mirrorsim budget scenes/bench/exp1.yaml (fresh renders)"):
            _wall(runs[label](-1))
        for label, argv in runs.items():
            times = [_wall(argv(k)) for k in range(a.repeat)]
            print(f"| `{label}` | {statistics.median(times):.2f} | "
                  f"{min(times):.2f}–{max(times):.2f} |", flush=True)


if __name__ == "__main__":
    main()
