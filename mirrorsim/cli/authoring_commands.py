"""Commands that write and check a scene without rendering it: ``new`` (a template or a
bundled scene), ``check`` (the exact ground truth) and ``plot`` (the top view)."""


from __future__ import annotations

from pathlib import Path

from mirrorsim.cli.outputs import out_file
from mirrorsim.cli.registry import command, common, emit, load, output
from mirrorsim.errors import BadArgument
from mirrorsim.formats.files import emit_json


def _new_options(p):
    from mirrorsim.formats.template import BUNDLED

    p.add_argument("scene", type=Path, help="the scene file to write (YAML; must not exist)")
    p.add_argument("--like", choices=BUNDLED,
                   help="a copy of this bundled scene instead of the template (default: the "
                        "paper's default bench; exp1-exp3: its experiments), named after "
                        "SCENE")


@command("new", "write a commented template scene",
         "Write SCENE: a complete scene with every key commented (a camera at the board's "
         "corner, a mirror, a target behind a wall, two pencil beacons), named after the "
         "file, that `mirrorsim check` accepts; or, with --like, one of the bundled scenes "
         "(the package carries them).  Edit it from there; docs/scenes.md lists every key.  "
         "An existing file is never written over.",
         options=_new_options)
def _new(args) -> int:
    from mirrorsim.formats.files import check_output_file, write_text
    from mirrorsim.formats.template import scene_template

    path = Path(args.scene)
    text = scene_template(path, args.like)  # refuses a name that cannot be a scene's
    if path.exists() or path.is_symlink():
        what = "a folder" if path.is_dir() else "a file"
        raise BadArgument("SCENE", f"{str(path)!r} exists ({what}): mirrorsim new writes only "
                                   "a new file; give a new name")
    check_output_file(path, "SCENE")
    write_text(path, text)
    made = f"a copy of the bundled {args.like}" if args.like else "a template scene"
    print(f"{path}: {made}; check it with `mirrorsim check {path}`")
    return 0


def _check_options(p):
    common(p, json="the exact ground truth")
    output(p, "--measurements", "file", metavar="FILE",
           help="write the exact (noise-free) measurements for `mirrorsim solve`")


@command("check", "validate a scene and say what the camera sees",
         "Validate SCENE and print, for the target and each beacon, its virtual image, alpha, "
         "d_total, reflection point and how much of its image reaches the camera through the "
         "mirror. No rendering.",
         options=_check_options)
def _check(args) -> int:
    from mirrorsim.cli.tables import check_table
    from mirrorsim.truth import groundtruth

    scene = load(args.scene)
    print(check_table(scene))
    truth = groundtruth.ground_truth(scene)
    emit(args, truth.to_json())
    if args.measurements:
        exact = (truth.exact_measurements3() if scene.is_3d  # (solve takes either)
                 else truth.exact_measurements())
        emit_json(args.measurements, {**exact.to_json(),
                                      "source": "exact geometry (mirrorsim check)"},
                  getattr(args, "json_stdout", None))
    return 0


def _plot_options(p):
    common(p, out="PNG to write (default renders/<name>/<name>.top.png)", out_kind="file")


@command("plot", "top view of a scene (board, camera, mirror, rays)",
         "Draw the top view: board, camera and its field of view, occluders, mirror, target, "
         "beacons, virtual images and rays.",
         options=_plot_options)
def _plot(args) -> int:
    from mirrorsim.cli.top_view import plot_top_view
    from mirrorsim.errors import SceneError
    from mirrorsim.pipelines.scenes import scene_and_failures

    try:
        scene = load(args.scene)
    except SceneError:
        # an invalid scene is drawn where its blocks can be read, its failures marked on
        # it, so that the user sees what is wrong; then they are raised as check's are
        # (each listed, exit 2)
        scene, failures = scene_and_failures(args.scene)
        if scene is None:
            raise
        out = out_file(args, scene, f"{scene.name}.top.png")
        print(f"{plot_top_view(scene, out, failures=failures)} (the scene is invalid: "
              f"{len(failures)} failure(s) marked)")
        first, *rest = failures
        first.others = tuple(rest)
        raise first from None
    print(plot_top_view(scene, out_file(args, scene, f"{scene.name}.top.png")))
    return 0
