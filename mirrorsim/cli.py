"""The ``mirrorsim`` command: argument parsing and printing only."""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

from mirrorsim.scene import SceneError, load_scene

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def _scene_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", type=Path, help="scene file (YAML, see INTERFACE.md)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mirrorsim",
        description="Physically rendered mirror space for NLOS localization (SLTR): "
                    "render scenes with exact ground truth, check and plot them.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("render", help="render the frame and write its ground truth",
                       description="Render SCENE with Mitsuba 3 and write DIR/<name>.png (sRGB, "
                       "8-bit), DIR/<name>.json (exact ground truth, with each object's "
                       "bbox_px and visible_px in the mirror from an object-id pass) and "
                       "DIR/<name>.ids.png (the id labels).")
    _scene_arg(p)
    p.add_argument("--out", type=Path, help="output folder (default renders/<name>/)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's, else 16)")
    p.add_argument("--seed", type=int, help="sampler seed (default: the scene's, else 0)")
    p.add_argument("--variant", default="auto",
                   choices=["auto", "cuda", "llvm", "scalar"],
                   help="Mitsuba backend; auto = cuda if a GPU works, else llvm if its probe "
                   "renders, else scalar (default: auto)")
    p.add_argument("--json", metavar="FILE", help="also write the ground truth here (- = stdout)")
    p.add_argument("--quiet", action="store_true", help="no progress line")

    p = sub.add_parser("check", help="validate a scene and say what the camera sees",
                       description="Validate SCENE and print, for the target and each beacon, "
                       "its virtual image, alpha, d_total, reflection point and how much of "
                       "its image reaches the camera through the mirror. No rendering.")
    _scene_arg(p)
    p.add_argument("--json", metavar="FILE", help="write the exact ground truth (- = stdout)")

    p = sub.add_parser("plot", help="top view of a scene (board, camera, mirror, rays)",
                       description="Draw the top view: board, camera and its field of view, "
                       "occluders, mirror, target, beacons, virtual images and rays.")
    _scene_arg(p)
    p.add_argument("--out", type=Path, help="PNG to write (default renders/<name>/<name>.top.png)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    warnings.showwarning = _one_line_warning
    try:
        return _COMMANDS[args.command](args)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"warning: {message}", file=sys.stderr)


def _load(path: Path):
    scene = load_scene(path)
    for w in scene.warnings:
        print(f"warning: {path}: {w}", file=sys.stderr)
    return scene


def _write_json(dest: str | None, data: dict) -> None:
    if dest is None:
        return
    text = json.dumps(data, indent=2) + "\n"
    if dest == "-":
        sys.stdout.write(text)
    else:
        Path(dest).write_text(text)


def _cmd_render(args) -> int:
    from mirrorsim.backend import BackendError
    from mirrorsim.render import render_scene

    scene = _load(args.scene)
    for flag, value in (("--spp", args.spp), ("--seed", args.seed)):
        if value is not None and value < (1 if flag == "--spp" else 0):
            print(f"error: {flag}: {value} must be ≥ {1 if flag == '--spp' else 0}",
                  file=sys.stderr)
            return EXIT_BAD_INPUT
    try:
        res = render_scene(scene, args.out, spp=args.spp, seed=args.seed,
                           variant=args.variant, progress=not args.quiet)
    except BackendError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    t = res.truth
    print(f"{scene.name}: {res.png} ({scene.camera.width}×{scene.camera.height_px}, "
          f"{t['render']['spp']} spp, {res.variant}, {res.seconds:.1f} s)")
    print(f"ground truth: {res.truth_json}")
    for label, e in [("target", t["target"])] + [(f"beacon {i}", b)
                                                  for i, b in enumerate(t["beacons"])]:
        print(f"  {label:<9} α {e['alpha_deg']:9.4f}°  d_total {e['d_total']:8.3f} cm  "
              f"in mirror: {e['visible_px']} px, bbox {e['bbox_px']}")
    _write_json(args.json, t)
    return 0


def _cmd_check(args) -> int:
    from mirrorsim import optics

    scene = _load(args.scene)
    cam = scene.camera
    print(f"{scene.name}: valid.  camera at {list(cam.position)}, height {cam.height:g} cm, "
          f"pan {cam.pan_deg:.3f}°, hfov {cam.hfov:g}°, {cam.width}×{cam.height_px} px, "
          f"fx {cam.fx:.2f} px")
    print(f"mirror: centre {list(scene.mirror.center)}, yaw {scene.mirror.yaw % 180:g}°, "
          f"{scene.mirror.size[0]:g} × {scene.mirror.size[1]:g} cm")
    print(f"{'object':<9} {'alpha°':>9} {'d_total':>8} {'d1':>7} {'d2':>7} "
          f"{'reflection pt':>16} {'on mirror':>9} {'u px':>7} {'h px':>6} {'seen':>5}")
    objs = [("target", scene.target)] + [(f"beacon {i}", b) for i, b in enumerate(scene.beacons)]
    for label, obj in objs:
        img = optics.mirror_image(cam, scene.mirror, obj.position)
        ext = optics.image_extent(scene, obj)
        vis = optics.visibility(scene, obj)
        rp = f"({img.reflection_point[0]:.2f}, {img.reflection_point[1]:.2f})"
        print(f"{label:<9} {img.alpha_deg:9.3f} {img.d_total:8.3f} {img.d1:7.2f} {img.d2:7.2f} "
              f"{rp:>16} {img.mirror_offset:+9.2f} {ext.u_axis:7.1f} {ext.height_px:6.1f} "
              f"{100 * vis.fraction:4.0f}%")
        if vis.reason:
            print(f"          {vis.reason}")
    direct = optics.direct_view_fraction(scene, scene.target)
    print("target is hidden from the camera's direct view (NLOS)" if direct == 0.0 else
          f"target is {100 * direct:.0f}% directly visible: not NLOS")
    _write_json(args.json, optics.ground_truth(scene))
    return 0


def _cmd_plot(args) -> int:
    from mirrorsim.plot import plot_top_view

    scene = _load(args.scene)
    out = args.out or Path("renders") / scene.name / f"{scene.name}.top.png"
    print(plot_top_view(scene, out))
    return 0


_COMMANDS = {"render": _cmd_render, "check": _cmd_check, "plot": _cmd_plot}


if __name__ == "__main__":
    sys.exit(main())
