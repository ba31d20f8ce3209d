"""Benchmark: wall time of a full-size render of a scene, per available Mitsuba variant.

    python benchmarks/render.py [--scene scenes/exp1.yaml] [--spp N] [--repeat K]
                           [--variants llvm scalar]

Each variant renders in its own child process (so a first-kernel JIT compile is
counted, as a user's single `mirrorsim render` would see it); the best of K runs is
reported, with the ratio to the fastest variant.  Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile

from clone import ROOT  # noqa: E402  (the clone first on sys.path)

from mirrorsim.rendering.backend import VARIANTS, probe  # noqa: E402

_CHILD = r"""
import json, sys, time
from mirrorsim.pipelines.scenes import load_scene
from mirrorsim.pipelines.frame import render_to_files
scene = load_scene(sys.argv[1])
t0 = time.perf_counter()
res = render_to_files(scene.with_render(spp=int(sys.argv[3])), sys.argv[2],
                      variant=sys.argv[4], progress=False)
print(json.dumps({"wall_s": time.perf_counter() - t0,
                  "render_s": res.truth.render.seconds_render,
                  "spp": res.truth.render.spp}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "exp1.yaml"))
    ap.add_argument("--spp", type=int, default=None, help="default: the scene's / 16")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=["cuda", "llvm", "scalar"],
                    choices=list(VARIANTS))
    args = ap.parse_args()

    from mirrorsim.pipelines.scenes import load_scene

    scene = load_scene(args.scene)
    spp = args.spp or scene.render.spp
    rows = []
    for short in args.variants:
        variant = VARIANTS[short]
        if short != "scalar":
            ok, why = probe(variant)
            if not ok:
                print(f"{variant}: unavailable ({why})", file=sys.stderr)
                continue
        times = []
        for k in range(args.repeat if short != "scalar" else 1):
            with tempfile.TemporaryDirectory() as tmp:
                proc = subprocess.run(
                    [sys.executable, "-c", _CHILD, args.scene, tmp, str(spp), short],
                    capture_output=True, text=True, cwd=ROOT, check=True)
            times.append(json.loads(proc.stdout.strip().splitlines()[-1]))
            print(f"{variant} run {k + 1}: {times[-1]['wall_s']:.2f} s", file=sys.stderr)
        best = min(times, key=lambda t: t["wall_s"])
        rows.append((variant, best["wall_s"], best["render_s"]))

    fastest = min(r[1] for r in rows)
    w, h = scene.camera.resolution
    print(f"\n{scene.name}, {w}×{h}, {spp} spp; {platform.processor() or platform.machine()}, "
          f"{_cores()} cores, Python {platform.python_version()}\n")
    print("| variant | wall (s) | path tracing (s) | × fastest |")
    print("|---|---|---|---|")
    for variant, wall, rend in rows:
        print(f"| {variant} | {wall:.2f} | {rend:.2f} | {wall / fastest:.1f} |")


def _cores() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


if __name__ == "__main__":
    main()
