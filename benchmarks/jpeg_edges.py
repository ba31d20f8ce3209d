"""Diagnostic: what JPEG does to each edge the detector measures, against the exact
projections, with the detector's way of measuring each edge and with plain colour.

    python benchmarks/jpeg_edges.py [--scenes 12] [--quality 90]

For scenes 0..N−1 of ``scenes/dataset_spec.yaml`` (an ideal bench), each frame is
rendered once and measured twice: as the lossless PNG, and as the same pixels stored as
JPEG at ``--quality`` (OpenCV's libjpeg, 4:2:0 chroma) and decoded.  The target's and
the mirror pencil's top and foot are measured in the detector's box around each image,
in five ways (each edge on the image's colour, or as the detector does: the target's
foot and the pencil's foot on the colour across the board's, the pencil's top on the
blue channel; or as it measures a frame of half-resolution colour, a JPEG: the pencil's
foot on the colour across the board's of the 8-bit values as stored, every other edge
on the image's colour), and compared with the exact projection of each object's front
face.
Prints the mean and spread over the scenes of each edge's offset (px, + is down) and of
the image height's error as a d_total error (%).  Chroma is what JPEG stores at half
resolution; a bias that differs between the two kinds is what a self-calibrated range
scale cannot absorb (docs/limitations.md).
"""

from __future__ import annotations

import argparse

import clone  # noqa: F401  (the clone first on sys.path)
import numpy as np
from exact import spec_scenes  # noqa: E402
from stamp import stamp  # noqa: E402

from mirrorsim.camera.sensor import to_srgb8  # noqa: E402
from mirrorsim.detection import area_edges, edges, regions  # noqa: E402
from mirrorsim.formats.files import decode_image, encode_jpeg  # noqa: E402
from mirrorsim.rendering.passes import render_frame  # noqa: E402
from mirrorsim.scene.model import pencil_paint_height  # noqa: E402
from mirrorsim.truth.optics import front_face  # noqa: E402

# (target foot on chroma, pencil top on blue, pencil foot on chroma): True is the
# detector's way for a lossless frame (edges.measure_region), False the image's colour;
# the pencil's foot may also be "stored": on the chroma of the 8-bit values as stored
WAYS = {"the detector's, lossless": (True, True, True),
        "target foot on colour": (False, True, True),
        "pencil top on colour": (True, False, True),
        "every edge on colour": (False, False, False),
        "the detector's, half-resolution colour": (False, False, "stored")}


def _exact(scene, obj, height: float, kind: str) -> tuple[float, float]:
    """Rows of the front face's top and foot in the mirror image."""
    _, v = front_face(scene, obj, height, kind=kind)
    return v[1], v[0]


def _measure(srgb: np.ndarray, scene, way, pencil_rows) -> tuple[tuple, tuple]:
    """(top, foot) of the target and of the mirror pencil, measured ``way``."""
    target_foot_chroma, pencil_top_blue, pencil_foot_chroma = way
    img = srgb.astype(np.float32)
    lin = edges.to_linear(img)
    u0, v0, u1, v1 = regions.find_target(img, scene.target.size[0] / scene.target.size[1])
    target = area_edges.median_edges((lin, lin), (v0, v1), (u0, u1), axis=0,
                                 chroma=(False, target_foot_chroma), near=(False, True))[:2]
    # the mirror pencil's box: the one whose rows are nearest its exact image's
    p0, q0, p1, q1 = min(regions.find_pencils(img), key=lambda b: abs(b[1] - pencil_rows[0])
                         + abs(b[3] - pencil_rows[1]))
    if pencil_foot_chroma == "stored":  # the detector's own JPEG way, not a copy of it
        m = edges.measure_region(lin, (p0, q0, p1, q1), "beacon", subsampled=True, stored=img)
        return target, (m.v_top, m.v_bottom)
    top_img = np.ascontiguousarray(lin[..., 2:3]) if pencil_top_blue else lin
    pencil = area_edges.median_edges((top_img, lin), (q0, q1), (p0, p1), axis=0,
                                 chroma=(False, pencil_foot_chroma), slope=(True, True))[:2]
    return target, pencil


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=12)
    ap.add_argument("--quality", type=int, default=90)
    a = ap.parse_args()
    print(f"edges against their exact projections, lossless and JPEG at quality {a.quality}, "
          f"scenes 0–{a.scenes - 1} of dataset_spec.yaml; {stamp()}\n")
    got = {(w, f): [] for w in WAYS for f in ("PNG", "JPEG")}
    unmeasured = []
    for s in spec_scenes(a.scenes):
        png = to_srgb8(render_frame(s.with_render(seed=0), progress=False).linear)
        frames = {"PNG": png, "JPEG": decode_image(encode_jpeg(png, a.quality))}
        t_true = _exact(s, s.target, s.target.size[1], "target")
        b = s.beacons[0]
        p_true = _exact(s, b, pencil_paint_height(b.height), "beacon")
        for w, way in WAYS.items():
            for f, img in frames.items():
                (tt, tf), (pt, pf) = _measure(img, s, way, p_true)
                if None in (tt, tf, pt, pf):  # an edge without contrast: not measured
                    unmeasured.append(f"{s.name} ({w}, {f})")
                    continue
                got[(w, f)].append((
                    tt - t_true[0], tf - t_true[1],
                    100 * ((t_true[1] - t_true[0]) / (tf - tt) - 1),
                    pt - p_true[0], pf - p_true[1],
                    100 * ((p_true[1] - p_true[0]) / (pf - pt) - 1)))
    print("mean ± SD over the scenes; px, + is down; d: the height's error as d_total's (%)\n")
    print("| edges measured | frame | target top | target foot | target d % | pencil top | "
          "pencil foot | pencil d % |\n|---|---|---|---|---|---|---|---|")
    for (w, f), rows in got.items():
        r = np.array(rows)
        print(f"| {w} | {f} ({len(rows)}) | " + " | ".join(f"{m:+.2f} ± {sd:.2f}" for m, sd in
                                             zip(r.mean(axis=0), r.std(axis=0), strict=True))
              + " |")
    if unmeasured:
        print(f"\nnot measured (an edge without contrast): {', '.join(unmeasured)}")


if __name__ == "__main__":
    main()
