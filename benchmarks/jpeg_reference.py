"""Diagnostic: the size-constancy references recorded as JPEG, as a lab calibrating with
its JPEG camera would record them.

    python benchmarks/jpeg_reference.py [--qualities 85 90 95]

For each camera model of ``scenes/dataset_spec_bench.yaml``, the calibration's two
reference objects (the target panel and the pencil, in direct view at 100 cm, as
:mod:`mirrorsim.pipelines.calibrate` renders them) are measured as a lossless frame, as
a JPEG frame is measured (``subsampled``: see ``edges.measure_region``), and
stored as JPEG at each quality (OpenCV's libjpeg, 4:2:0 chroma; the crop's corner on the
frame's 16 px block grid) and decoded, then measured the JPEG way.  Prints each pixel
height and its difference from the lossless one (%): a K calibrated through JPEG carries
that difference into every d_total of the kind.  Compare with what JPEG does to the
same kinds in frames (``benchmarks/jpeg_edges.py``).
"""

from __future__ import annotations

import argparse

from clone import ROOT  # noqa: E402  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

from mirrorsim.detection.detector import measure_object  # noqa: E402
from mirrorsim.formats.files import decode_image, encode_jpeg  # noqa: E402
from mirrorsim.pipelines import calibrate as cal  # noqa: E402
from mirrorsim.pipelines.random_scenes import camera_models, load_spec  # noqa: E402
from mirrorsim.rendering.passes import render_direct  # noqa: E402
from mirrorsim.scene.model import Board  # noqa: E402

BLOCK_PX = 16  # a 4:2:0 JPEG's blocks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qualities", type=int, nargs="+", default=[85, 90, 95])
    a = ap.parse_args()
    spec = load_spec(ROOT / "scenes" / "dataset_spec_bench.yaml")
    print("calibration references (100 cm, direct view) recorded as JPEG; pixel heights "
          f"and their difference from the lossless frame's; {stamp()}\n")
    qs = " | ".join(f"JPEG q{q}" for q in a.qualities)
    print(f"| camera (hfov, height) | object | lossless (px) | lossless, JPEG's way | {qs} |")
    print("|---|---|---" + "|---" * (1 + len(a.qualities)) + "|")
    board = Board(size=(80.0, 80.0), hole_pitch=0.0)  # as the calibration's
    for model in camera_models(spec):
        for kind, size in (("target", tuple(spec.target_size)), ("beacon", spec.beacon_height)):
            film = cal.reference_film(model, kind, size)  # (as calibrate renders it)
            cam = cal.reference_camera(model, film)
            obj = cal.reference_object(kind, size)
            u0, v0, u1, v1 = cal.reference_crop(cam, obj)
            crop = (u0 - u0 % BLOCK_PX, v0 - v0 % BLOCK_PX, u1, v1)
            srgb = render_direct(board, cam, obj, spp=cal.CALIBRATION_SPP[kind], crop=crop)
            ratio = size[0] / size[1] if kind == "target" else None

            base = measure_object(srgb, kind, ratio).height_px / film
            cells = [f"{base:.2f}"]
            for img in [srgb] + [decode_image(encode_jpeg(srgb, q)) for q in a.qualities]:
                h = measure_object(img, kind, ratio, subsampled=True).height_px / film
                cells.append(f"{h:.2f} ({100 * (h / base - 1):+.2f} %)")
            name = "pencil's band" if kind == "beacon" else "target"
            print(f"| {model.hfov:g}°, {model.height:g} cm | {name} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
