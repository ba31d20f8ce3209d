"""Benchmark: dataset throughput (scenes per minute: draw + render + detect + solve + write).

    python benchmarks/dataset.py [--n 24] [--workers 1 2] [--variants llvm] [--spp N]
                            [--sampler independent|multijitter] [--seed S] [--warm-kernels]

For each variant and worker count, a fresh dataset of N full-size scenes of the default
spec is made in a temporary folder, and the scenes per minute of wall time (the whole
`mirrorsim dataset` process) are reported.  What a user's new dataset gets: a seed never
rendered before (a fresh one drawn unless --seed) and an empty Dr.Jit kernel cache (a
fresh HOME for the run, whose ~/.drjit is Dr.Jit's cache; --warm-kernels keeps the
user's).  The spec's camera models are calibrated beforehand by a one-scene dataset, as
after a user's first run (mirrorsim's own cache is kept).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time

from clone import ROOT  # noqa: E402  (the clone first on sys.path)

from mirrorsim.formats.cache import cache_root  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--variants", nargs="+", default=["llvm"])
    ap.add_argument("--spp", type=int)
    ap.add_argument("--sampler")
    ap.add_argument("--seed", type=int, help="default: a fresh one, printed")
    ap.add_argument("--warm-kernels", action="store_true",
                    help="keep Dr.Jit's kernel cache (default: an empty one)")
    a = ap.parse_args()
    seed = a.seed if a.seed is not None else int.from_bytes(os.urandom(3), "big")
    extra = (["--spp", str(a.spp)] if a.spp else []) + (
        ["--sampler", a.sampler] if a.sampler else [])
    with tempfile.TemporaryDirectory() as tmp:  # calibrates the spec's camera models
        subprocess.run([sys.executable, "-m", "mirrorsim", "dataset", "--n", "1", "--seed",
                        "0", "--out", f"{tmp}/ds", "--quiet", *extra], cwd=ROOT, check=True,
                       capture_output=True)
    print(f"dataset throughput, {a.n} scenes of 1920×1088 ({' '.join(extra) or 'defaults'}), "
          f"seed {seed}, {'warm' if a.warm_kernels else 'empty'} kernel cache; "
          f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}\n")
    print("| variant | workers | wall (s) | scenes/min |\n|---|---|---|---|")
    for v in a.variants:
        for w in a.workers:
            with tempfile.TemporaryDirectory() as tmp:
                cmd = [sys.executable, "-m", "mirrorsim", "dataset", "--n", str(a.n), "--seed",
                       str(seed), "--out", f"{tmp}/ds", "--workers", str(w), "--variant", v,
                       "--quiet", *extra]
                env = dict(os.environ)
                env.setdefault("MIRRORSIM_CACHE_DIR", str(cache_root()))  # the user's
                if not a.warm_kernels:
                    env["HOME"] = tmp  # Dr.Jit keeps its kernels in ~/.drjit
                t0 = time.perf_counter()
                proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env)
                wall = time.perf_counter() - t0
            if proc.returncode:
                print(f"| {v} | {w} | failed: {proc.stderr.strip()[-80:]} | |")
                continue
            print(f"| {v} | {w} | {wall:.1f} | {a.n / wall * 60:.1f} |", flush=True)


if __name__ == "__main__":
    main()
