"""Diagnostic: the pencil's painted band against its exact projection, over scenes of
the dataset spec, with its image rendered at many samples (the steady part).

    python benchmarks/pencil_edges.py [--scenes 12] [--spp 128]

For scenes 0..N−1 of ``scenes/dataset_spec.yaml``: the frame at the spec's settings
(seed 0), and again with the beacon's image box at ``--spp`` (``render.beacon_spp``,
seed 1), each measured as the detector measures it; prints per scene the top's and
foot's offsets from the projection of the pencil's front face (px) with the box at
``--spp``, and the beacon's d_total error (%) both ways, and the spread of each.
"""

from __future__ import annotations

import argparse
import platform
from dataclasses import replace  # noqa: E402

import clone  # noqa: F401  (the clone first on sys.path)
import numpy as np
from exact import spec_scenes  # noqa: E402

from mirrorsim.camera.sensor import to_srgb8  # noqa: E402
from mirrorsim.detection.detector import detect_frame  # noqa: E402
from mirrorsim.formats.capture import CaptureRecord  # noqa: E402
from mirrorsim.pipelines.calibrate import calibrate  # noqa: E402
from mirrorsim.rendering.passes import render_frame  # noqa: E402
from mirrorsim.scene.model import pencil_paint_height  # noqa: E402
from mirrorsim.truth import optics  # noqa: E402
from mirrorsim.truth.optics import front_face  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=12)
    ap.add_argument("--spp", type=int, default=128)
    a = ap.parse_args()
    print(f"pencil edges, scenes 0–{a.scenes - 1} of the spec, 1920×1088, the box at "
          f"{a.spp} spp; {platform.machine()}\n")
    print("| scene | top px | foot px | Δd/d % (box at spp) | Δd/d % (spec's settings) |\n"
          "|---|---|---|---|---|")
    rows = []
    for s in spec_scenes(a.scenes):
        cal = calibrate(s.camera, s.target.size, s.beacons[0].height)
        frame = render_frame(s.with_render(spp=s.render.spp, seed=0), progress=False)
        many = replace(s, render=replace(s.render, beacon_spp=a.spp))
        sharp = render_frame(many.with_render(spp=s.render.spp, seed=1), progress=False)
        cap = CaptureRecord.from_scene(s, frame=f"{s.name}.png")
        b = s.beacons[0]
        img = optics.mirror_image(s.camera.position, s.mirror, b.position)
        _, v = front_face(s, b, pencil_paint_height(b.height), kind="beacon")
        errs = []
        for f in (sharp, frame):
            m = detect_frame(to_srgb8(f.linear), cap, cal).beacons[0][1]
            errs.append((m, 100 * (m.d_total - img.d_total) / img.d_total))
        (m, e_hi), (_, e_spec) = errs
        rows.append((m.v_top - v[1], m.v_bottom - v[0], e_hi, e_spec))
        print(f"| {s.name} | {rows[-1][0]:+.3f} | {rows[-1][1]:+.3f} | {e_hi:+.3f} | "
              f"{e_spec:+.3f} |", flush=True)
    r = np.array(rows)
    print(f"\nmean / SD: top {r[:, 0].mean():+.3f} / {r[:, 0].std():.3f} px, foot "
          f"{r[:, 1].mean():+.3f} / {r[:, 1].std():.3f} px, Δd/d at {a.spp} spp "
          f"{r[:, 2].mean():+.3f} / {r[:, 2].std():.3f} %; median |Δd/d| "
          f"{np.median(abs(r[:, 2])):.3f} % ({a.spp} spp), {np.median(abs(r[:, 3])):.3f} % "
          "(spec's settings)")


if __name__ == "__main__":
    main()
