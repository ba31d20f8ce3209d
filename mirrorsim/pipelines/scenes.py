"""Where a scene enters: a file, a parsed document, an edit, a scene given to the API.
Each entry point reads (:mod:`mirrorsim.formats.scenefile`), then composes
(:func:`mirrorsim.truth.compose.compose_scene`): the one way a :class:`Scene` is made
whole.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from mirrorsim.errors import BadParameter, Failures, SceneError
from mirrorsim.formats.files import jsonable
from mirrorsim.formats.scenefile import parse_scene, read_scene_file, scene_document
from mirrorsim.scene.model import Scene, check_is_scene
from mirrorsim.truth.compose import compose_scene


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file.

    Raises
    ------
    SceneError
        For any bad input, with the file, the key path and what is wrong.
    """
    f = Failures()
    scene, bkey = read_scene_file(path, failures=f)
    return compose_scene(scene, beacon_key=bkey, failures=f)


def scene_from_dict(data: Any, source: str = "<scene>", default_name: str = "scene") -> Scene:
    """Build and validate a :class:`Scene` from parsed YAML (see docs/scenes.md).

    Raises
    ------
    SceneError
        The first failure, with every other one found in the file in ``others``: the
        blocks are read independently, and the checks between objects (on the board,
        in front of the mirror, overlaps, sight) each run where their blocks were read.
    """
    f = Failures()
    scene, bkey = parse_scene(data, source=source, default_name=default_name, failures=f)
    return compose_scene(scene, beacon_key=bkey, failures=f)


def scene_and_failures(path: str | Path) -> tuple[Scene | None, tuple[SceneError, ...]]:
    """A scene file read as far as it goes: the scene (None where a block cannot be read)
    and every failure found, for ``mirrorsim plot`` to draw an invalid scene with its
    failures marked.  Never raises SceneError."""
    path = Path(path)
    f = Failures(lenient=True)
    try:
        scene, bkey = read_scene_file(path, failures=f)
        scene = compose_scene(scene, beacon_key=bkey, failures=f)
    except SceneError as exc:
        return None, (exc, *exc.others)
    return scene, tuple(f.found)


def edit_scene(scene: Scene, changes: Mapping[str, Any]) -> Scene:
    """``scene`` with some of its file's keys changed, built again as a scene file is:
    every check runs, and what the file's geometry decides (the target panel's facing, a
    pan aimed with ``mirror``, ``target`` or ``beacon``) follows the edit.
    ``dataclasses.replace`` recomputes none of it.

    ``changes`` nests as the file does, ``{"mirror": {"yaw": 20}, "name": "yaw20"}``: a
    mapping merges into its block, whose other keys keep their values (a beacon moved by
    ``{"beacon": {"position": …}}`` keeps a ``known_position`` its file gave), and any
    other value (a list too: ``beacons``) replaces its key.  numpy numbers are taken as
    numbers.

    Raises
    ------
    SceneError
        An edit the file's checks refuse, naming its key (the source reads
        ``SOURCE (edited)``).
    BadParameter
        ``changes`` is not a mapping.
    """
    check_is_scene(scene)
    if not isinstance(changes, Mapping):
        raise BadParameter("changes", f"expected a mapping of scene-file keys, not "
                           f"{type(changes).__name__}")
    doc = scene_document(scene)
    if "beacons" in changes:  # the one-beacon form gives way to the list given
        doc.pop("beacon", None)
    elif "beacon" in changes and "beacons" in doc:
        raise BadParameter("changes", f"beacon: {scene.name} has {len(scene.beacons)} beacons; "
                           "give `beacons`, the whole list")
    # numpy numbers (a script's np.arange of yaws) as a file's; NaN left to be refused
    plain = jsonable(changes, nonfinite_as_null=False)
    edited = scene_from_dict(_merged(doc, plain), source=f"{scene.source} (edited)",
                             default_name=scene.name)
    return replace(edited, source=scene.source)


def _merged(doc: dict, changes: Mapping[str, Any]) -> dict:
    out = dict(doc)
    for key, value in changes.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def check_given_scene(scene: Any) -> Scene:
    """A scene given to the Python API, held to what its file would make of it: a scene
    edited with ``dataclasses.replace`` skips the file's checks and keeps the target's
    facing and the pan that its old geometry decided (a mirror turned by 10° left the
    panel facing the old mirror).  The scene is composed as given (no file is written
    and read again); returns ``scene``.

    Raises
    ------
    SceneError
        The edited scene fails a check of the scene file (naming the key).
    BadParameter
        ``scene`` is not a :class:`Scene`, or what its geometry decides has not followed
        an edit (use :func:`edit_scene`).
    """
    check_is_scene(scene)
    # each value was held to its bounds when its dataclass was made (an edit too); the
    # bench's, the relations and the derived fields are the composer's
    again = compose_scene(replace(scene, source=f"{scene.source} (edited)"))
    stale = [what for what, given, made in (
        ("target panel's facing", scene.target.facing_deg, again.target.facing_deg),
        ("camera's pan bearing", scene.camera.pan_deg, again.camera.pan_deg))
        if not math.isclose(given, made, rel_tol=0, abs_tol=1e-9)]
    if stale:
        raise BadParameter("scene", f"{scene.name}: the {' and the '.join(stale)} no longer "
                           f"follow{'s' if len(stale) == 1 else ''} its geometry (edited with "
                           "dataclasses.replace, which recomputes nothing): edit it with "
                           "mirrorsim.edit_scene")
    return scene


def refuse_3d(scene: Scene, command: str) -> None:
    """Refuse a 3-D scene (a raised object or mirror, a leaning mirror) where ``command``
    works in the board's plane only: one line naming the scene's file and the first key
    that makes it 3-D, before anything is claimed or rendered.

    Raises
    ------
    SceneError
        ``scene`` is 3-D.
    """
    if not scene.is_3d:
        return
    key, value = scene.raised()[0]
    raise SceneError(scene.source, key, f"{value:g}: {command} works in the board's plane "
                     "and this scene is 3-D; `evaluate` solves it in 3-D")
