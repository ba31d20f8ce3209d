"""Diagnostic: what JPEG does to each edge the detector measures, on the same renders.

    python benchmarks/jpeg_edges.py [--scenes 12] [--quality 90]

For scenes 0..N−1 of ``scenes/dataset_spec.yaml`` (an ideal bench), each frame is
rendered once and measured twice: as the lossless PNG, and as the same pixels stored as
JPEG at ``--quality`` (OpenCV's libjpeg, 4:2:0 chroma) and decoded.  Prints per scene
how far JPEG moves the target's and the pencil's top and foot (px, + is down) and their
d_total (%), then the mean and spread of each.  A bias that differs between the two
kinds is what a self-calibrated range scale cannot absorb (docs/limitations.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from stamp import stamp  # noqa: E402

from mirrorsim.detection.detector import detect_frame  # noqa: E402
from mirrorsim.formats.capture import CaptureRecord  # noqa: E402
from mirrorsim.formats.files import decode_image, encode_jpeg  # noqa: E402
from mirrorsim.pipelines.calibrate import calibrate  # noqa: E402
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene  # noqa: E402
from mirrorsim.rendering.passes import render_frame  # noqa: E402
from mirrorsim.rendering.sensor import to_srgb8  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=12)
    ap.add_argument("--quality", type=int, default=90)
    a = ap.parse_args()
    spec = load_spec(ROOT / "scenes" / "dataset_spec.yaml")
    print(f"JPEG at quality {a.quality} against the lossless frame, scenes 0–{a.scenes - 1} "
          f"of dataset_spec.yaml; {stamp()}\n")
    print("| scene | target top px | target foot px | target d % | pencil top px | "
          "pencil foot px | pencil d % |\n|---|---|---|---|---|---|---|")
    rows = []
    for i in range(a.scenes):
        s = sample_scene(spec, np.random.SeedSequence(0, spawn_key=(i,)), f"spec{i:03d}")
        cal = calibrate(s.camera, s.target.size, s.beacons[0].height)
        png = to_srgb8(render_frame(s.with_render(seed=0), progress=False).linear)
        jpg = decode_image(encode_jpeg(png, a.quality))
        cap = CaptureRecord.from_scene(s, frame=f"{s.name}.png")
        d0, d1 = (detect_frame(img, cap, cal) for img in (png, jpg))
        (t0, p0), (t1, p1) = ((d.target, d.beacons[0][1]) for d in (d0, d1))
        row = (t1.v_top - t0.v_top, t1.v_bottom - t0.v_bottom,
               100 * (t1.d_total / t0.d_total - 1),
               p1.v_top - p0.v_top, p1.v_bottom - p0.v_bottom,
               100 * (p1.d_total / p0.d_total - 1))
        rows.append(row)
        print(f"| {s.name} | " + " | ".join(f"{v:+.3f}" for v in row) + " |", flush=True)
    r = np.array(rows)
    print("| **mean** | " + " | ".join(f"**{v:+.3f}**" for v in r.mean(axis=0)) + " |")
    print("| SD | " + " | ".join(f"{v:.3f}" for v in r.std(axis=0)) + " |")
    print(f"\npencil d − target d (the part a shared scale misapplies): mean "
          f"{(r[:, 5] - r[:, 2]).mean():+.3f} %, SD {(r[:, 5] - r[:, 2]).std():.3f} %")


if __name__ == "__main__":
    main()
