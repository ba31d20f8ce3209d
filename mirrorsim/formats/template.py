"""The scenes ``mirrorsim new`` writes: the commented template, or a copy of a bundled
scene, each named after the file it goes to.  Both are the package's data, so that a
wheel installed away from the clone writes them too."""

from __future__ import annotations

import json
import re
from pathlib import Path

from mirrorsim.errors import BadParameter, SceneError
from mirrorsim.scene.model import NAME_PATTERN

# the bundled scenes ``mirrorsim new --like`` copies (the package's data/scenes/)
BUNDLED = ("default", "exp1", "exp2", "exp3")


def scene_template(path: str | Path, like: str | None = None) -> str:
    """The commented template scene (``mirrorsim new``), named after ``path``'s stem; or,
    with ``like``, that bundled scene (:data:`BUNDLED`) renamed so.

    Raises
    ------
    SceneError
        When the file's name cannot be a scene's name.
    BadParameter
        A ``like`` that names no bundled scene.
    """
    from importlib import resources

    name = Path(path).stem
    if not NAME_PATTERN.fullmatch(name):
        raise SceneError(str(path), "", f"{name!r} cannot name a scene (letters, digits, "
                                        "'.', '_', '-'; starting with a letter or digit)")
    data = resources.files("mirrorsim") / "data"
    if like is None:
        text = (data / "template.yaml").read_text(encoding="utf-8")
        # quoted: a name such as 123, yes or null would read as another type
        return text.replace("name: NAME ", f"name: {json.dumps(name)} ", 1)
    if like not in BUNDLED:
        raise BadParameter("like", f"{like!r}: choose one of {', '.join(BUNDLED)}")
    text = (data / "scenes" / f"{like}.yaml").read_text(encoding="utf-8")
    return re.sub(r"(?m)^name: .*$", f"name: {json.dumps(name)}", text, count=1)
