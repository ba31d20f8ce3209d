"""The side view of a 3-D scene (``mirrorsim plot`` draws it beside the top view): a
section across the mirror, where its lean, the objects' heights and their leaning
virtual images show."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mirrorsim.scene.model import Scene
from mirrorsim.truth import optics

if TYPE_CHECKING:
    from matplotlib.axes import Axes


def draw_side_view(ax: Axes, scene: Scene) -> None:
    """Board, camera, mirror (leaning, on its pedestal), the target and the beacons on
    their posts and their virtual images, seen along the mirror's line: across it, s is
    the distance in front of the mirror's bottom edge (the camera's side positive), z
    the height."""
    m, cam = scene.mirror, scene.camera
    plane = optics.mirror_plane(cam, m)
    face = np.array([plane.normal[0], plane.normal[1]]) / np.hypot(*plane.normal[:2])
    foot = np.asarray(m.center, float)

    def across(p) -> tuple[float, float]:
        p = np.asarray(p, float)
        return float((p[:2] - foot) @ face), float(p[2])

    lean = np.radians(m.lean)
    top = (-m.size[1] * np.sin(lean), m.z + m.size[1] * np.cos(lean))
    ax.axhline(0.0, color="#8a6d3b", lw=2, zorder=1)
    ax.plot([0.0, top[0]], [m.z, top[1]], color="#2a7fbf", lw=4, zorder=4,
            label=f"mirror (lean {m.lean:g}°)")
    if m.z:
        ax.plot([0.0, 0.0], [0.0, m.z], color="0.25", lw=3, zorder=3, label="pedestal")
    s_cam, z_cam = across(cam.center3)
    ax.plot(s_cam, z_cam, marker="s", color="k", ms=8, zorder=5, label="camera")
    objects = [("target", scene.target, scene.target.size[1], "#c0392b")] + [
        (f"beacon {i}" if len(scene.beacons) > 1 else "beacon", b, b.height, "#d4a017")
        for i, b in enumerate(scene.beacons)]
    xs = [s_cam, 0.0, top[0]]
    for label, obj, h, colour in objects:
        base = obj.base3
        s, z = across(base)
        ax.plot([s, s], [z, z + h], color=colour, lw=4, zorder=5,
                label=f"{label} ({obj.z:g} cm up)")
        if obj.z:
            ax.plot([s, s], [0.0, z], color="0.3", lw=1.2, zorder=4)
        v_foot, v_top = (across(p) for p in plane.reflect(np.array([base, base + [0, 0, h]])))
        ax.plot([v_foot[0], v_top[0]], [v_foot[1], v_top[1]], color=colour, lw=2, ls="--",
                zorder=4)
        img = optics.image3(cam, m, base)
        r = across(img.reflection_point)
        ax.plot([s_cam, r[0], s], [z_cam, r[1], z], color=colour, lw=0.8, zorder=3)
        ax.plot([r[0], v_foot[0]], [r[1], v_foot[1]], color=colour, lw=0.6, ls=":", zorder=3)
        xs += [s, v_foot[0], v_top[0]]
    ax.set_xlim(min(xs) - 5, max(xs) + 5)
    ax.set_aspect("equal")
    ax.set_xlabel("s: in front of the mirror's bottom edge (cm)")
    ax.set_ylabel("z (cm)")
    ax.set_title(f"{scene.name}: side view across the mirror (dashed: virtual images)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=2, fontsize=7)
    ax.grid(alpha=0.2)
