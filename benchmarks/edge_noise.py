"""Benchmark: the render noise in the pencil's edges, by spp.

    python benchmarks/edge_noise.py [--spp 4 8] [--scenes 4] [--seeds 6]

Scenes 0..N−1 of the default spec, each rendered with several seeds at each spp
(uniform, the spec's sampler), detected; prints per scene the spread (standard
deviation over the seeds) of the pencil's top, foot and side edges in px and of its
d_total in %, and the mean signed d_total error (its steady part).
"""

from __future__ import annotations

import argparse
import platform
import tempfile
from dataclasses import replace
from pathlib import Path

import clone  # noqa: F401  (the clone first on sys.path)
import numpy as np

from mirrorsim.pipelines.calibrate import calibrate  # noqa: E402
from mirrorsim.pipelines.frame import render_and_measure  # noqa: E402
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 8])
    ap.add_argument("--scenes", type=int, default=4)
    ap.add_argument("--seeds", type=int, default=6)
    a = ap.parse_args()
    spec = load_spec(None)
    tmp = Path(tempfile.mkdtemp())
    print(f"pencil edge noise, default spec, 1920×1088, {a.seeds} seeds per scene; "
          f"{platform.machine()}\n")
    print("| spp | scene | σ top px | σ foot px | σ left px | σ right px | σ Δd/d % | "
          "mean Δd/d % |\n|---|---|---|---|---|---|---|---|")
    for spp in a.spp:
        for i in range(a.scenes):
            s = sample_scene(spec, np.random.SeedSequence(0, spawn_key=(i,)), f"s{i}")
            s = replace(s, render=replace(s.render, spp=spp, background_spp=spp))
            cal = calibrate(s.camera, s.target.size, s.beacons[0].height)
            rows = []
            for seed in range(a.seeds):
                m = render_and_measure(s.with_render(seed=seed), tmp / f"{spp}_{i}_{seed}",
                                       progress=False, ids=False, calibration=cal)
                res, mb = m.files, m.detection.beacons[0][1]
                d = res.truth.beacons[0].d_total
                rows.append((mb.v_top, mb.v_bottom, mb.u_left, mb.u_right,
                             100 * (mb.d_total - d) / d))
            r = np.array(rows, float)
            sd, mean = r.std(axis=0), r.mean(axis=0)
            print(f"| {spp} | {i} | {sd[0]:.3f} | {sd[1]:.3f} | {sd[2]:.3f} | {sd[3]:.3f} | "
                  f"{sd[4]:.3f} | {mean[4]:+.3f} |", flush=True)


if __name__ == "__main__":
    main()
