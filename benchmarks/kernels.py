"""Benchmark: what a new scene costs in a warm process, and the kernels it compiles.

    python benchmarks/kernels.py [--scenes 3] [--variant llvm]

Renders (``render_frame``, full size) the default scene, the same scene again, then
``--scenes`` scenes whose mirror, target and beacon stand elsewhere by amounts drawn
afresh (so that no earlier run's kernel cache serves them), with another seed each;
prints each render's wall time and the Dr.Jit kernels it launched and compiled (its
kernel history).  Stamped with commit, date and machine.
"""

from __future__ import annotations

import argparse
import copy
import time

import numpy as np
import yaml
from clone import ROOT  # noqa: E402  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

from mirrorsim.pipelines.scenes import scene_from_dict  # noqa: E402
from mirrorsim.rendering.passes import render_frame  # noqa: E402


def _scene(shift: np.ndarray, seed: int):
    d = copy.deepcopy(yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text()))
    dx, dy, db = (float(v) for v in shift)
    d["mirror"]["center"] = [d["mirror"]["center"][0] + dx, d["mirror"]["center"][1] + dy]
    d["target"]["position"][0] += dx
    d["beacon"]["position"][1] += db
    d["render"] = {**d.get("render", {}), "seed": seed}
    return scene_from_dict(d, "shifted.yaml", "shifted")


def main() -> None:
    import drjit as dr

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=3)
    ap.add_argument("--variant", default="llvm")
    a = ap.parse_args()
    print(f"{stamp()}, variant {a.variant}\n")
    print("| render | wall (s) | kernels launched | compiled | compile (s) |\n"
          "|---|---|---|---|---|")
    rng = np.random.default_rng()
    runs = [("the default scene", np.zeros(3), 0), ("the same again", np.zeros(3), 0)] + [
        (f"a new scene {k + 1}", rng.uniform(-1.0, 1.0, 3), int(rng.integers(1 << 30)))
        for k in range(a.scenes)]
    for label, shift, seed in runs:
        scene = _scene(shift, seed)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # emptied
        t0 = time.perf_counter()
        render_frame(scene, variant=a.variant, progress=False)
        wall = time.perf_counter() - t0
        hist = [h for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT]
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        new = [h for h in hist if not h["cache_hit"]]
        compile_s = sum(h["codegen_time"] + h["backend_time"] for h in new) / 1000
        print(f"| {label} | {wall:.2f} | {len(hist)} | {len(new)} | {compile_s:.2f} |",
              flush=True)


if __name__ == "__main__":
    main()
