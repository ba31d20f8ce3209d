"""Diagnostic: each measured edge of the target and the pencil against the exact
projection of the object's front face (where a steady bias in d_total or α comes from).

    python benchmarks/edges.py [--scene default] [--spp 16] [--offaxis 0]

Renders the bundled scene (panned so that the target's image lies ``--offaxis`` degrees
off the axis, α − pan), measures the target and the pencil's mirror image as the
detector does, and prints each edge's exact row or column, the measured one and the
difference in px; then the first-order shift of the target's edges by Mitsuba's ray offset at
the glass, with the world in the board's frame and centred on the glass.
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np
import yaml
from clone import ROOT  # noqa: E402  (the clone first on sys.path)

from mirrorsim.detection.detector import measure_object, to_linear
from mirrorsim.detection.edges import measure_region  # noqa: E402
from mirrorsim.detection.frame_files import read_frame
from mirrorsim.detection.regions import find_pencils  # noqa: E402
from mirrorsim.pipelines.frame import render_to_files  # noqa: E402
from mirrorsim.pipelines.scenes import scene_from_dict  # noqa: E402
from mirrorsim.scene.model import (  # noqa: E402
    PENCIL_RADIUS,
    TARGET_THICKNESS,
    pencil_paint_height,
)
from mirrorsim.truth import optics, visibility  # noqa: E402
from solver.geometry import reflect, unit  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="default")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--offaxis", type=float, default=0.0)
    a = ap.parse_args()
    d = yaml.safe_load((ROOT / "scenes" / f"{a.scene}.yaml").read_text())
    ref = scene_from_dict(d)
    alpha = optics.mirror_image(ref.camera.position, ref.mirror, ref.target.position).alpha_deg
    d["camera"]["pan"] = float(alpha - a.offaxis)
    s = scene_from_dict(d, default_name="edges")
    with tempfile.TemporaryDirectory() as tmp:
        res = render_to_files(s.with_render(spp=a.spp), tmp, progress=False)
        img = read_frame(res.image).astype(np.float32)
    t = s.target
    m = measure_object(img, "target", t.size[0] / t.size[1])
    front = np.asarray(t.position) + unit(t.facing_deg) * TARGET_THICKNESS / 2
    across = unit(t.facing_deg + 90)
    corners = [[*reflect(front + k * across * t.size[0] / 2, s.mirror.center, s.mirror.yaw), z]
               for k in (-1, 1) for z in (0.0, t.size[1])]
    c = reflect(front, s.mirror.center, s.mirror.yaw)
    u, v, _ = optics.project(s.camera, np.array(corners + [[*c, 0.0], [*c, t.size[1]]]))
    rows = [("target left", min(u[:4]), m.u_left), ("target right", max(u[:4]), m.u_right),
            ("target top", v[5], m.v_top), ("target foot", v[4], m.v_bottom)]
    b = s.beacons[0]
    ub, vvb = optics.front_face(s, b, pencil_paint_height(b.height), kind="beacon")
    lin = to_linear(img)
    pencils = [measure_region(lin, box, "beacon") for box in find_pencils(img)]
    p = min(pencils, key=lambda q: abs(np.nanmean([q.u_left or np.nan, q.u_right or np.nan])
                                       - ub[0]))
    # the hexagon's corners (mirrorsim.rendering.shapes.pencil_meshes) at mid-paint height,
    # reflected: its silhouette's columns
    ang = np.deg2rad(np.arange(6) * 60.0 + 30.0)
    ring = np.asarray(b.position) + PENCIL_RADIUS * np.stack([np.cos(ang), np.sin(ang)], 1)
    zc = pencil_paint_height(b.height) / 2
    uh, _, _ = optics.project(s.camera, np.array(
        [[*reflect(q, s.mirror.center, s.mirror.yaw), zc] for q in ring]))
    rows += [("pencil left", uh.min(), p.u_left), ("pencil right", uh.max(), p.u_right),
             ("pencil paint top", vvb[1], p.v_top), ("pencil foot", vvb[0], p.v_bottom)]
    print(f"{a.scene}, {a.offaxis:+g}° off axis, {a.spp} spp, {s.camera.width}×"
          f"{s.camera.height_px}\n\n| edge | exact px | measured px | difference px |\n"
          "|---|---|---|---|")
    for name, exact, meas in rows:
        diff = "—" if meas is None else f"{meas - exact:+.3f}"
        shown = "—" if meas is None else f"{meas:.3f}"
        print(f"| {name} | {exact:.3f} | {shown} | {diff} |")
    print("\nMitsuba's ray offset at the glass, first order (each reflected ray starts "
          "(1 + max|p|)·2⁻²⁴·1500 cm along the normal: the image moves by that, "
          "projected), target left / right, px:")
    g, along, up, n = visibility.glass_frame(s)
    real = np.array([[*(front + k * across * t.size[0] / 2), t.size[1] / 2] for k in (-1, 1)])
    virtual = np.array([[*reflect(q[:2], s.mirror.center, s.mirror.yaw), q[2]] for q in real])
    ga, gb, _ = visibility.glass_hits(s, real)
    hits = g + np.outer(ga, along) + np.outer(gb, up)
    u0 = optics.project(s.camera, virtual)[0]
    order = np.argsort(u0)  # left, right
    for label, origin in (("world = board frame", np.zeros(3)),
                          ("world centred on the glass", g)):
        mag = (1 + np.abs(hits - origin).max(axis=1)) * 2.0**-24 * 1500
        du = (optics.project(s.camera, virtual + mag[:, None] * n)[0] - u0)[order]
        print(f"  {label}: {du[0]:+.3f} / {du[1]:+.3f}")


if __name__ == "__main__":
    main()
