"""The top view of a scene, drawn once: what ``mirrorsim plot`` writes (with an invalid
scene's failures marked where their keys stand) and what the evaluation picture draws
its estimate on."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mirrorsim.formats.files import save_figure  # noqa: E402
from mirrorsim.scene.model import Scene  # noqa: E402
from mirrorsim.truth import optics  # noqa: E402
from solver.geometry import unit  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.axes import Axes

# a virtual image's label moves aside of an earlier one nearer than this (cm)
LABEL_NEAR_CM = 4.0


def plot_top_view(scene: Scene, out: str | Path, *, dpi: int = 150,
                  failures: tuple = ()) -> Path:
    """Draw board, camera and field of view, occluders, mirror, target, beacons,
    virtual images and the rays camera → mirror → object (a 3-D scene: with its side
    view beside, :func:`~mirrorsim.cli.side_view.draw_side_view`); write a PNG
    atomically.
    ``failures`` (SceneErrors of an invalid scene): each marked in red where its key's
    object stands, and listed under the view."""
    if not failures and scene.is_3d:  # a side view across the mirror beside it
        from mirrorsim.cli.side_view import draw_side_view

        fig, (ax, side) = plt.subplots(1, 2, figsize=(15, 7.5))
        draw_top_view(ax, scene)
        draw_side_view(side, scene)
        return save_figure(fig, Path(out), dpi)
    if not failures:
        fig, ax = plt.subplots(figsize=(7.5, 7.5))
        draw_top_view(ax, scene)
        return save_figure(fig, Path(out), dpi)
    lines = 0.2 * sum(1 + len(f"{e.key}: {e.message}") // 110 for e in failures)
    fig, (ax, listing) = plt.subplots(2, 1, figsize=(7.5, 7.5 + lines),
                                      gridspec_kw={"height_ratios": [7.5, lines]})
    draw_top_view(ax, scene)
    _mark_failures(ax, listing, scene, failures)
    return save_figure(fig, Path(out), dpi)


def _failure_place(scene: Scene, key: str):
    """Where a failing key's object stands (None where it has no place)."""
    head = key.split(".")[0]
    if head == "target":
        return scene.target.position
    if head.startswith("beacon"):
        i = int(head[len("beacons["):-1]) if head.startswith("beacons[") else 0
        return scene.beacons[i].position if i < len(scene.beacons) else None
    if head == "mirror":
        return scene.mirror.center
    if head == "camera":
        return scene.camera.position
    if head.startswith("occluders["):
        o = scene.occluders[int(head[len("occluders["):-1])]
        return (np.asarray(o.start, float) + np.asarray(o.end, float)) / 2
    return None


def _mark_failures(ax, listing, scene: Scene, failures: tuple) -> None:
    import textwrap

    places: dict[tuple[float, float], list[str]] = {}
    for k, e in enumerate(failures, 1):
        place = _failure_place(scene, e.key)
        if place is not None:
            places.setdefault(tuple(map(float, place)), []).append(str(k))
    for place, numbers in places.items():
        ax.plot(*place, "x", color="red", ms=16, mew=3, zorder=10)
        ax.annotate(",".join(numbers), place, textcoords="offset points", xytext=(9, -14),
                    color="red", weight="bold", fontsize=10, zorder=10,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "w", "ec": "red", "alpha": 0.8})
    # every marked object in view, however far off the board it stands
    xs = [*ax.get_xlim(), *(p[0] for p in places)]
    ys = [*ax.get_ylim(), *(p[1] for p in places)]
    ax.set_xlim(min(xs) - 3, max(xs) + 3)
    ax.set_ylim(min(ys) - 3, max(ys) + 3)
    ax.set_title(f"{scene.name}: INVALID, {len(failures)} failure(s) marked", color="red")
    listing.axis("off")
    text = "\n".join(textwrap.fill(f"{k}. {e.key}: {e.message}", 110,
                                    subsequent_indent="    ")
                      for k, e in enumerate(failures, 1))
    listing.text(0.0, 1.0, text, color="red", fontsize=7, va="top", ha="left",
                 transform=listing.transAxes)


def draw_top_view(ax: Axes, scene: Scene) -> None:
    """Board, camera and its field of view, walls, mirror, target and beacons with their
    virtual images and rays, on ``ax``."""
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
    _draw_images(ax, scene, objects)
    t0, t1 = scene.target.ends()
    ax.plot(*zip(t0, t1, strict=True), color="#c0392b", lw=3, zorder=5)

    pts = [np.array([0, 0]), np.array([sx, sy])]
    pts += [optics.object_image(scene, o).virtual[:2] for _, o, *_ in objects]
    pts = np.array(pts)
    lo, hi = pts.min(axis=0) - 5, pts.max(axis=0) + 5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    ax.set_title(f"{scene.name}: top view (dashed: to the virtual images)")
    legend_below(ax)
    ax.grid(alpha=0.2)


def _draw_images(ax: Axes, scene: Scene, objects: list[tuple]) -> None:
    """Each object (label, object, colour, marker, size), its virtual image and the ray
    through the mirror; the images' labels kept apart."""
    cam = scene.camera
    c = np.asarray(cam.position, float)
    placed: list[np.ndarray] = []  # the virtual images labelled so far
    for label, obj, colour, marker, ms in objects:
        img = optics.object_image(scene, obj)  # (a 3-D scene's: drawn in plan)
        p, v, r = np.asarray(obj.position, float), img.virtual[:2], img.reflection_point[:2]
        ax.plot(*zip(c, r, p, strict=True), color=colour, lw=1.2, zorder=3)
        ax.plot(*zip(r, v, strict=True), color=colour, lw=0.9, ls="--", zorder=3)
        ax.plot(*p, marker=marker, color=colour, ms=ms, mec="k", zorder=6,
                label=f"{label}: α {img.alpha_deg:.2f}°, d_total {img.d_total:.2f} cm")
        ax.plot(*v, marker=marker, color="none", mec=colour, ms=ms, zorder=6)
        # images a few cm apart (beacons side by side) had their labels on top of each
        # other: each further one near an earlier one goes a line lower, on the left
        near = sum(float(np.hypot(*(v - q))) < LABEL_NEAR_CM for q in placed)
        placed.append(np.asarray(v, float))
        ax.annotate(f"{label}′", v, textcoords="offset points", fontsize=8, color=colour,
                    xytext=(6 if near % 2 == 0 else -6, 4 - 11 * near),
                    ha="left" if near % 2 == 0 else "right")


def legend_below(ax: Axes) -> None:
    """The top view's legend under it: inside, it hid the virtual images and their
    labels, which stand beyond the board's far edge."""
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2, fontsize=7,
              framealpha=0.9)

