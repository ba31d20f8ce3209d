"""Regenerate the pictures of the README and the docs (run from the repository root;
``make docs`` runs it after ``docs/regenerate.py``):

    python docs/make_images.py

Evaluates the default scene (render, detect, solve), draws its top view and the
placement analysis of exp3, and saves downscaled JPEG copies of the frame and of the
annotated detections (the full PNGs stay in renders/); renders the default scene's
mirror flat, concave and convex side by side (bench imperfections); draws the default
frame's annotations (masks, boxes, keypoints).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image  # installed with matplotlib

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def run(*args: str) -> None:
    """Run a mirrorsim command."""
    subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", *args], cwd=ROOT, check=True)


def main() -> None:
    """Make the pictures of the README and the docs."""
    run("evaluate", "scenes/default.yaml", "--quiet", "--keep", "annotated", "plot")
    (DOCS / "default_eval.png").write_bytes(
        (ROOT / "renders" / "default" / "default.eval.png").read_bytes())
    run("plot", "scenes/default.yaml", "--out", str(DOCS / "default_top.png"))
    run("plan", "scenes/exp3.yaml", "--out", str(DOCS / "plan_exp3.png"))
    # the budget's tornado chart, as `mirrorsim budget scenes/bench/exp1.yaml` (the
    # budget_exp1 result of docs/regenerate.py) drew it: made again here where absent
    chart = ROOT / "renders" / "exp1_bench" / "budget" / "budget.png"
    if not chart.exists():
        run("budget", "scenes/bench/exp1.yaml", "--quiet")
    (DOCS / "budget_exp1.png").write_bytes(chart.read_bytes())
    run("detect", "renders/default/default.png", "--scene", "scenes/default.yaml",
        "--annotate", str(ROOT / "renders" / "default" / "default.annotated.png"))
    ann = np.asarray(Image.open(ROOT / "renders" / "default" / "default.annotated.png"))
    Image.fromarray(ann[300:720, 700:1240]).save(DOCS / "default_annotated.jpg", quality=90)
    frame = np.asarray(Image.open(ROOT / "renders" / "default" / "default.png").convert("RGB"))
    Image.fromarray(frame).resize((960, 544), Image.LANCZOS).save(DOCS / "default_frame.jpg",
                                                                  quality=88)
    Image.fromarray(frame[330:720, 760:1180]).save(DOCS / "default_mirror_crop.jpg", quality=92)
    curved_mirrors()
    scene3d()
    annotations_picture()


def annotations_picture() -> None:
    """The default scene's frame with its annotations drawn (docs/annotations.md): each
    instance's mask tinted by category, its box, and its keypoints (filled: seen)."""
    import cv2

    import mirrorsim as ms
    from mirrorsim.formats import rle

    files = ms.render(ms.load_scene(ROOT / "scenes" / "default.yaml"),
                      ROOT / "renders" / "default_annotations", progress=False)
    img = np.asarray(Image.open(files.image).convert("RGB")).astype(np.float32)
    colours = {"target_in_mirror": (230, 60, 60), "beacon_in_mirror": (40, 200, 255),
               "beacon_direct": (60, 220, 60), "target_direct": (255, 160, 0),
               "mirror": (170, 90, 255)}
    ann = files.truth.annotations
    # the glass first, then what it shows over it
    for inst in sorted(ann.instances, key=lambda i: i.category != "mirror"):
        mask = rle.decode(inst.mask)
        img[mask] = 0.55 * img[mask] + 0.45 * np.array(colours[inst.category])
    out = np.ascontiguousarray(img.clip(0, 255).astype(np.uint8))
    for inst in ann.instances:
        c = colours[inst.category]
        x, y, w, h = inst.bbox
        cv2.rectangle(out, (x, y), (x + w - 1, y + h - 1), c, 1)
        cv2.putText(out, inst.category, (x, y - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.5, c, 1,
                    cv2.LINE_AA)
        for k in inst.keypoints:
            centre = (int(round(k.u)), int(round(k.v)))
            cv2.circle(out, centre, 4, (255, 255, 255), -1 if k.visible == 2 else 1,
                       cv2.LINE_AA)
            cv2.circle(out, centre, 4, (0, 0, 0), 1, cv2.LINE_AA)
    Image.fromarray(out[280:760, 700:1300]).save(DOCS / "annotations.jpg", quality=90)


def scene3d() -> None:
    """The bundled 3-D scene as rendered (its mirror's part, enlarged) and its top and
    side views (`mirrorsim plot`)."""
    run("render", "scenes/raised.yaml", "--out", "renders/raised", "--quiet")
    frame = np.asarray(Image.open(ROOT / "renders" / "raised" / "raised.png").convert("RGB"))
    Image.fromarray(frame[400:760, 700:1250]).save(DOCS / "scene3d_frame.jpg", quality=90)
    run("plot", "scenes/raised.yaml", "--out", str(DOCS / "scene3d_views.png"))


def curved_mirrors(radius: float = 300.0) -> None:
    """The default scene's mirror flat, concave and convex (radius ±R cm): the same crop
    of each full-size frame, side by side."""
    import yaml

    base = yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text())
    crops = []
    for label, r in (("flat", None), ("concave", radius), ("convex", -radius)):
        d = {**base, "name": f"default_{label}", "mirror": dict(base["mirror"])}
        if r is not None:
            d["mirror"]["curvature_radius"] = r
        # the scene files beside, the frames in their own output folder
        path = ROOT / "renders" / "docs_scenes" / f"default_{label}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(yaml.safe_dump(d))
        out = ROOT / "renders" / "docs" / label
        out.parent.mkdir(parents=True, exist_ok=True)  # render makes its folder, not above
        run("render", str(path), "--quiet", "--out", str(out))
        img = np.asarray(Image.open(out / f"default_{label}.png").convert("RGB"))
        crops.append(img[360:700, 800:1120])
    gap = np.full((crops[0].shape[0], 8, 3), 255, np.uint8)
    Image.fromarray(np.hstack([crops[0], gap, crops[1], gap, crops[2]])).save(
        DOCS / "curved_mirror.jpg", quality=90)


if __name__ == "__main__":
    main()
