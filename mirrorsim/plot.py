"""Top views of a scene (like the paper's Figs. 2 and 7), drawn with matplotlib."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; no display on the machines this runs on
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mirrorsim import optics  # noqa: E402
from mirrorsim.scene import Scene  # noqa: E402
from solver.geometry import unit  # noqa: E402


def plot_top_view(scene: Scene, out: str | Path, *, dpi: int = 150) -> Path:
    """Draw board, camera and field of view, occluders, mirror, target, beacons,
    virtual images and the rays camera → mirror → object; write a PNG atomically."""
    out = Path(out)
    fig, ax = plt.subplots(figsize=(7.5, 7.5))
    sx, sy = scene.board.size
    ax.add_patch(plt.Rectangle((0, 0), sx, sy, facecolor="#e8d4b0", edgecolor="#8a6d3b",
                               lw=1.2, zorder=0, label="board"))
    if scene.board.hole_pitch > 0:
        p = scene.board.hole_pitch
        g = np.arange(p / 2, min(sx, sy), p)
        gx, gy = np.meshgrid(g[g < sx], g[g < sy])
        ax.plot(gx.ravel(), gy.ravel(), ".", ms=1.2, color="#8a6d3b", alpha=0.5, zorder=0)

    cam = scene.camera
    c = np.asarray(cam.position, float)
    reach = 1.5 * float(np.hypot(sx, sy))
    for edge in (-1, 1):
        e = c + reach * unit(cam.pan_deg + edge * cam.hfov / 2)
        ax.plot(*zip(c, e, strict=True), color="0.5", lw=0.8, ls=":", zorder=1)
    ax.plot(*zip(c, c + 12 * unit(cam.pan_deg), strict=True), color="k", lw=1.0, zorder=3)
    ax.plot(*c, marker="s", color="k", ms=8, zorder=5, label=f"camera (pan {cam.pan_deg:.1f}°)")

    for i, o in enumerate(scene.occluders):
        ax.plot(*zip(o.start, o.end, strict=True), color="#555", lw=5, solid_capstyle="butt",
                zorder=2, label="occluder" if i == 0 else None)

    m0, m1 = scene.mirror.ends()
    d = m1 - m0
    ext0, ext1 = m0 - 3 * d, m1 + 3 * d
    ax.plot(*zip(ext0, ext1, strict=True), color="#2a7fbf", lw=0.6, ls="--", zorder=1)
    ax.plot(*zip(m0, m1, strict=True), color="#2a7fbf", lw=4, zorder=4,
            label=f"mirror (yaw {scene.mirror.yaw % 180:.1f}°)")

    objects = [("target", scene.target, "#c0392b", "*", 14)]
    objects += [(f"beacon {i}" if len(scene.beacons) > 1 else "beacon", b, "#d4a017", "o", 7)
                for i, b in enumerate(scene.beacons)]
    for label, obj, colour, marker, ms in objects:
        img = optics.mirror_image(cam, scene.mirror, obj.position)
        p, v, r = np.asarray(obj.position, float), img.virtual, img.reflection_point
        ax.plot(*zip(c, r, p, strict=True), color=colour, lw=1.2, zorder=3)
        ax.plot(*zip(r, v, strict=True), color=colour, lw=0.9, ls="--", zorder=3)
        ax.plot(*p, marker=marker, color=colour, ms=ms, mec="k", zorder=6,
                label=f"{label}: α {img.alpha_deg:.2f}°, d_total {img.d_total:.2f} cm")
        ax.plot(*v, marker=marker, color="none", mec=colour, ms=ms, zorder=6)
        ax.annotate(f"{label}′", v, textcoords="offset points", xytext=(6, 4), fontsize=8,
                    color=colour)
    t0, t1 = scene.target.ends()
    ax.plot(*zip(t0, t1, strict=True), color="#c0392b", lw=3, zorder=5)

    pts = [np.array([0, 0]), np.array([sx, sy])]
    pts += [optics.mirror_image(cam, scene.mirror, o.position).virtual for _, o, *_ in objects]
    pts = np.array(pts)
    lo, hi = pts.min(axis=0) - 5, pts.max(axis=0) + 5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    ax.set_title(f"{scene.name}: top view (dashed: to the virtual images)")
    ax.legend(loc="upper left", fontsize=7, framealpha=0.9)
    ax.grid(alpha=0.2)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}.png")
    try:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
        os.replace(tmp, out)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return out
