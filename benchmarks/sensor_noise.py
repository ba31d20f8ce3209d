"""Benchmark: sensor noise's effect on the target's measurements against first order.

    python benchmarks/sensor_noise.py [--full-well 6000 1500] [--read-noise 4]

The default scene at half size (960 × 544, 8 spp) rendered ideal and with shot and read
noise at each full well (same render seed: the frames differ by the sensor noise
alone).  Beside each measured shift of the target's α and d_total stands the first-order
spread that noise gives an edge found from the coverage of 3 pixels per row (√3·σ_I/ΔI
px, σ_I the channels' mean noise at the edge's level, ΔI the step there, read off the
ideal frame at the id pass's box), the median of N rows (× 1.25/√N), the bearing from
two edges, the height from two.  ``tests/test_bench.py`` holds the bearing to it.
"""

from __future__ import annotations

import argparse
import copy
import math
import platform
import tempfile
from pathlib import Path

import numpy as np
import yaml
from clone import ROOT  # noqa: E402  (the clone first on sys.path)

from mirrorsim.camera.sensor import srgb8_to_linear  # noqa: E402
from mirrorsim.pipelines.frame import render_and_measure  # noqa: E402
from mirrorsim.pipelines.scenes import scene_from_dict  # noqa: E402


def scene(noise: dict | None = None):
    d = copy.deepcopy(yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text()))
    d["camera"]["resolution"] = [960, 544]
    d["render"] = {"spp": 8}
    if noise:
        d["camera"]["noise"] = noise
    return scene_from_dict(d, source="sensor_noise", default_name="default")


def edge_sigma(inside: float, outside: float, fw: float, rn: float, n: int) -> float:
    """First-order spread (px) of an edge's median position over n rows or columns."""
    level = (inside + outside) / 2
    s_i = math.sqrt(level / fw + (rn / fw) ** 2) / math.sqrt(3)
    return 1.2533 * math.sqrt(3) * s_i / abs(inside - outside) / math.sqrt(n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full-well", type=float, nargs="+", default=[6000.0, 1500.0])
    ap.add_argument("--read-noise", type=float, default=4.0)
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="sensor_noise"))
    s0 = scene()
    m0 = render_and_measure(s0, tmp / "ideal", progress=False)
    lin = srgb8_to_linear(m0.image).mean(axis=2)
    u0, v0, u1, v1 = m0.files.truth.target.bbox_px
    rows, cols = slice(v0 + (v1 - v0) // 4, v1 - (v1 - v0) // 4), slice(u0 + 4, u1 - 4)
    inside = float(np.median(lin[rows, cols]))
    side = [float(np.median(lin[rows, u0 - 7:u0 - 3])), float(np.median(lin[rows, u1 + 3:u1 + 7]))]
    ends = [float(np.median(lin[v0 - 7:v0 - 3, cols])), float(np.median(lin[v1 + 3:v1 + 7, cols]))]
    height = m0.files.truth.target.image_px.height
    print(f"# sensor noise against first order ({platform.machine()}, Python "
          f"{platform.python_version()})\n")
    print("| full well (e⁻) | Δα (°) | first-order σ_α (°) | Δα/σ | Δd/d (%) | "
          "first-order σ_d (%) | Δd/σ |\n|---|---|---|---|---|---|---|")
    for fw in a.full_well:
        m = render_and_measure(scene({"full_well": fw, "read_noise": a.read_noise}),
                               tmp / f"fw{fw:g}", progress=False)
        s_a = math.degrees(math.hypot(*(edge_sigma(inside, o, fw, a.read_noise, v1 - v0)
                                        for o in side)) / 2 / s0.camera.fx)
        s_d = math.hypot(*(edge_sigma(inside, o, fw, a.read_noise, u1 - u0)
                           for o in ends)) / height
        da = m.detection.target.alpha_deg - m0.detection.target.alpha_deg
        dd = (m.detection.target.d_total - m0.detection.target.d_total) \
            / m0.detection.target.d_total
        print(f"| {fw:g} | {da:+.5f} | {s_a:.5f} | {da / s_a:+.1f} | {100 * dd:+.4f} | "
              f"{100 * s_d:.4f} | {dd / s_d:+.1f} |")


if __name__ == "__main__":
    main()
