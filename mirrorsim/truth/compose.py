"""The scene composed once: whatever made a :class:`Scene` (a file, an edit, a random
draw), :func:`compose_scene` derives what its geometry decides and runs the checks
between its objects.

The scene reader (:mod:`mirrorsim.formats.scenefile`) only parses: each block's keys and
values, with the derived fields (the target panel's facing, the camera's pan bearing)
left NaN.  The entry points (:mod:`mirrorsim.pipelines.scenes`) read, then compose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from mirrorsim.errors import Failures, SceneError
from mirrorsim.scene.bench_values import bench_failures
from mirrorsim.scene.model import Bench, Scene
from mirrorsim.truth import optics
from mirrorsim.truth.scene_checks import (
    board_check,
    check_all_on_board,
    check_limits,
    check_mirror_faces,
    check_overlaps,
    check_sight,
    check_under_glass,
    fmt,
    unit_hints,
)


def default_beacon_key(scene: Scene) -> Callable[[int], str]:
    """How a scene file names beacon ``i``: ``beacon`` alone, ``beacons[i]`` in a list."""
    if len(scene.beacons) == 1:
        return lambda _i: "beacon"
    return lambda i: f"beacons[{i}]"


def with_facing(scene: Scene) -> Scene:
    """``scene`` with its target panel facing the camera's virtual image in its mirror,
    unchecked (the composer's; the tracker's believed scene, whose pan stays the one
    the camera was set to)."""
    cam, target = scene.camera, scene.target
    return replace(scene, target=replace(target, facing_deg=optics.target_facing(
        cam, scene.mirror, target.position)))


def with_derived(scene: Scene) -> Scene:
    """``scene`` with what its geometry decides computed, unchecked: the target's facing
    (:func:`with_facing`), and a pan given as a word (``mirror``, ``target``,
    ``beacon``) as a bearing.  The one place these are derived."""
    scene = with_facing(scene)
    cam, mirror, target = scene.camera, scene.mirror, scene.target
    pan_deg = optics.resolve_pan(cam, cam.pan, mirror, target=target, beacon=scene.beacons[0])
    return replace(scene, camera=replace(cam, pan_deg=pan_deg))


def compose_scene(scene: Scene, *, beacon_key: Callable[[int], str] | None = None,
                  failures: Failures | None = None) -> Scene:
    """``scene`` made whole and checked: its bench's values held to their bounds (which
    relate some of them to the mirror and the camera), its derived fields computed
    (:func:`with_derived`) and its objects checked against each other (on the board, in
    front of the mirror's face, apart, seen through the mirror), its warnings set.

    Parameters
    ----------
    scene
        A scene whose values are each valid (read by the scene reader, or edited); its
        derived fields may be stale or NaN.
    beacon_key
        How the failures name beacon ``i`` (``beacon`` or ``beacons[i]``, as its file
        wrote it); by default as a file of its beacons would.
    failures
        Where failures are collected (the reader's, so that ``check`` lists the file's
        all); a lenient one (``plot``) lets a scene that fails be composed anyway.

    Raises
    ------
    SceneError
        The first failure, naming ``scene.source`` and the key path, the others in
        ``others``.
    """
    f = Failures() if failures is None else failures
    bkey = beacon_key or default_beacon_key(scene)

    def fail(key: str, message: str) -> SceneError:
        return SceneError(scene.source, key, message)

    # the file's limits, and each bench value within its bounds (some relate it to the
    # mirror or the camera): said as they are, without a unit hint
    check_limits(f, scene, fail, bkey=bkey)
    f.found += [fail(key, why) for key, why in bench_failures(scene)]
    if f.found and f.lenient:  # (plot: a bad bench key drawn as the ideal)
        scene = replace(scene, bench=Bench())
    f.raise_any()
    cam, mirror, target, beacons = scene.camera, scene.mirror, scene.target, scene.beacons
    hint = unit_hints(scene.board, mirror, cam.hfov, positions=[
        ("camera.position", cam.position), ("mirror.center", mirror.center),
        ("target.position", target.position),
        *((f"{bkey(i)}.position", b.position) for i, b in enumerate(beacons))])
    on_board = board_check(fail, scene.board)
    check_all_on_board(f, on_board, cam.position, mirror=mirror, target_position=target.position,
                       beacons=beacons, bkey=bkey,
                       occluders=scene.occluders)
    f.raise_any(hint)
    f.attempt(check_mirror_faces, f, fail, cam.position, mirror=mirror,
              target_position=target.position, beacons=beacons, bkey=bkey)
    f.raise_any(hint)
    scene = with_derived(scene)
    for end in scene.target.ends():
        f.attempt(on_board, end, "target.position", f"the target panel's edge {fmt(end)}")
    f.raise_any(hint)
    check_overlaps(f, scene, fail, bkey=bkey)
    check_under_glass(f, scene, fail, bkey=bkey)
    warnings = check_sight(f, scene, fail, bkey=bkey)
    f.raise_any(hint)
    return replace(scene, warnings=warnings)
