"""The house's boundaries, one test per wing (the rules of the README's *Architecture*).

Each test reads the code's own imports (``ast``, so lazy imports inside functions count
too) or imports a wing in a fresh interpreter and lists what it loaded.
"""

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "mirrorsim"
# the wings in the order data flows through them: a wing imports only wings before it
WINGS = ("scene", "formats", "truth", "camera", "rendering", "detection", "pipelines", "cli")
SHARED = {"errors", "arguments", "progress", "__init__"}  # the errors, the API's argument
# check, the progress bars and the package's face: for every wing
DATA = "data"  # files shipped with the package (the default error model); no code


def _modules(folder: Path) -> list[Path]:
    return sorted(folder.rglob("*.py"))


def _imports(path: Path) -> set[str]:
    """Every module ``path`` imports, at the top or inside a function."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
            # `from mirrorsim.truth import optics` imports the module mirrorsim.truth.optics
            out |= {f"{node.module}.{a.name}" for a in node.names}
    return out


def _loaded_by(module: str) -> set[str]:
    """The modules a fresh interpreter holds after importing ``module``."""
    code = f"import sys, json; import {module}; print(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, check=True)
    return set(json.loads(done.stdout))


def test_every_module_sits_in_a_wing():
    loose = [p.name for p in PACKAGE.glob("*.py") if p.stem not in SHARED | {"__main__"}]
    assert loose == []
    assert {p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__"} \
        == {*WINGS, DATA}
    assert not list((PACKAGE / DATA).rglob("*.py"))


@pytest.mark.parametrize("wing", WINGS)
def test_a_wing_imports_only_the_wings_before_it(wing):
    later = WINGS[WINGS.index(wing) + 1:]
    bad = [(p.relative_to(ROOT).as_posix(), m) for p in _modules(PACKAGE / wing)
           for m in _imports(p) if m.split(".")[0] == "mirrorsim" and len(m.split(".")) > 1
           and m.split(".")[1] in later]
    assert bad == []


def test_the_detector_never_loads_the_truth():
    # the detector's whole import closure: no optics, no ground truth, no scene-file
    # reader (so it cannot read a scene's mirror or target), no Mitsuba
    loaded = _loaded_by("mirrorsim.detection.detector")
    forbidden = [m for m in loaded if m.startswith((
        "mirrorsim.truth", "mirrorsim.formats.scene", "mirrorsim.pipelines", "mitsuba",
        "drjit"))]
    assert "mirrorsim.detection.detector" in loaded
    assert forbidden == []


def test_the_detection_wing_names_no_truth_even_lazily():
    bad = [(p.name, m) for p in _modules(PACKAGE / "detection") for m in _imports(p)
           if m.startswith(("mirrorsim.truth", "mirrorsim.formats.scene"))]
    assert bad == []


def test_the_solver_is_pure_mathematics():
    allowed_roots = {"__future__", "dataclasses", "math", "typing", "collections", "functools",
                     "itertools", "enum", "numpy", "scipy", "solver"}
    for p in _modules(ROOT / "solver"):
        roots = {m.split(".")[0] for m in _imports(p)}
        assert roots <= allowed_roots, (p.name, roots - allowed_roots)
        # no file I/O: no open(), no pathlib, no reading or writing text
        names = {n.id for n in ast.walk(ast.parse(p.read_text())) if isinstance(n, ast.Name)}
        attrs = {n.attr for n in ast.walk(ast.parse(p.read_text()))
                 if isinstance(n, ast.Attribute)}
        assert not names & {"open", "Path"}, p.name
        assert not attrs & {"read_text", "write_text", "read_bytes", "write_bytes", "load",
                            "dump"}, p.name
    loaded = _loaded_by(", ".join(f"solver.{p.stem}" for p in _modules(ROOT / "solver")
                                  if p.stem != "__init__"))
    assert [m for m in loaded if m.startswith(("mirrorsim", "mitsuba", "drjit", "cv2"))] == []


def test_the_sensor_model_is_below_rendering_and_detection():
    """The camera's sensor and lens model is its own wing: the detector undoes what the
    renderer applies without importing the renderer (it once did, in three places)."""
    bad = [(p.relative_to(ROOT).as_posix(), m) for p in _modules(PACKAGE / "detection")
           for m in _imports(p) if m.startswith("mirrorsim.rendering")]
    assert bad == []
    loaded = _loaded_by("mirrorsim.detection.detector")
    assert [m for m in loaded if m.startswith(("mirrorsim.rendering", "mitsuba"))] == []


def test_rendering_reads_no_scene_file():
    """The renderer renders a Scene it is given: the file reader and its checks belong
    to the entry points (``ms.render`` is ``pipelines.frame.render_to_files``)."""
    bad = [(p.name, m) for p in _modules(PACKAGE / "rendering") for m in _imports(p)
           if m.startswith(("mirrorsim.formats.scenefile", "mirrorsim.truth.scene_checks",
                            "mirrorsim.truth.compose", "mirrorsim.pipelines.scenes"))]
    assert bad == []


def test_the_file_reader_only_parses():
    """``formats/`` reads files: it imports nothing of the truth (the optics, the checks
    between objects, the composer); the wing order holds it, and this says why."""
    bad = [(p.name, m) for p in _modules(PACKAGE / "formats") for m in _imports(p)
           if m.startswith("mirrorsim.truth")]
    assert bad == []


# what only the composer derives, and where a scene is made whole
DERIVED = ("target_facing", "resolve_pan")
COMPOSES = ("compose_scene", "with_derived", "with_facing")


def _calls(path: Path) -> set[str]:
    """The names ``path`` calls (``f(…)`` or ``module.f(…)``)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call):
            fn = node.func
            out.add(fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", ""))
    return out


def test_a_scene_is_composed_in_one_place():
    """The target's facing and the pan are derived by the composer alone
    (``truth/compose.py``), and a scene is composed only where it enters
    (``pipelines/scenes.py``) or where the tracker believes one (``track_paths.py``)."""
    derives = sorted(p.relative_to(PACKAGE).as_posix() for p in _modules(PACKAGE)
                     if _calls(p) & set(DERIVED))
    assert derives == ["truth/compose.py"]
    composes = sorted(p.relative_to(PACKAGE).as_posix() for p in _modules(PACKAGE)
                      if _calls(p) & set(COMPOSES))
    assert composes == ["pipelines/scenes.py", "pipelines/track_paths.py", "truth/compose.py"]


def test_no_scene_is_written_out_to_be_checked():
    """A scene is checked by composing it, not by writing it back into a file's document
    and reading that again: only an edit (which merges into the file's keys) and a
    dataset's scene files turn a scene into a document."""
    users = sorted(p.relative_to(PACKAGE).as_posix() for p in _modules(PACKAGE)
                   if "scene_document" in _calls(p))
    assert users == ["pipelines/random_scenes.py", "pipelines/scenes.py"]
    # and the API's check of a scene it is given composes that scene, never a document
    tree = ast.parse((PACKAGE / "pipelines" / "scenes.py").read_text(encoding="utf-8"))
    given = next(n for n in tree.body if isinstance(n, ast.FunctionDef)
                 and n.name == "check_given_scene")
    called = {getattr(c.func, "id", getattr(c.func, "attr", "")) for c in ast.walk(given)
              if isinstance(c, ast.Call)}
    assert "compose_scene" in called
    assert not called & {"scene_document", "parse_scene", "scene_from_dict"}


def test_rendering_imports_no_detection():
    bad = [(p.name, m) for p in _modules(PACKAGE / "rendering") for m in _imports(p)
           if m.startswith(("mirrorsim.detection", "cv2.aruco"))]
    assert bad == []
    loaded = _loaded_by("mirrorsim.rendering.frames")
    assert [m for m in loaded if m.startswith("mirrorsim.detection")] == []


def test_only_rendering_touches_mitsuba():
    bad = [(p.relative_to(ROOT).as_posix(), m) for p in _modules(PACKAGE)
           if p.parent.name != "rendering" for m in _imports(p)
           if m.split(".")[0] in ("mitsuba", "drjit")]
    assert bad == []


FLAG = re.compile(r"(?<![\w-])--[a-z]")


def test_the_library_raises_no_error_naming_a_flag():
    # only the command line knows flags: library errors name parameters
    # (errors.BadParameter), and cli.main maps them to flags
    bad = []
    for p in _modules(PACKAGE):
        if p.parent.name == "cli":
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Raise) and node.exc is not None:
                for c in ast.walk(node.exc):
                    if isinstance(c, ast.Constant) and isinstance(c.value, str) \
                            and FLAG.search(c.value):
                        bad.append((p.relative_to(ROOT).as_posix(), node.lineno, c.value))
    assert bad == []


def test_no_import_circle():
    graph = {}
    for p in _modules(PACKAGE) + _modules(ROOT / "solver"):
        rel = p.relative_to(ROOT).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        graph[name] = {m for m in _imports(p) if m.split(".")[0] in ("mirrorsim", "solver")}
    # an import of a package counts as an import of its face (__init__), which imports
    # nothing here; keep only edges to modules that exist
    graph = {k: {m for m in v if m in graph and m != k} for k, v in graph.items()}
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                raise AssertionError(" -> ".join([*path, node, nxt]))
            if nxt not in state:
                visit(nxt, [*path, node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])


# warnings.showwarning's signature, which Python calls by position
POSITIONAL_PROTOCOL = {"one_line_warning"}


def _long_positional(path: Path) -> list[str]:
    """Public functions and methods of ``path`` taking more than three arguments by
    position (``self`` and ``cls`` aside)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    funcs = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    funcs += [m for c in tree.body if isinstance(c, ast.ClassDef) and not c.name.startswith("_")
              for m in c.body if isinstance(m, ast.FunctionDef)]
    return [f"{path.name}:{fn.lineno} {fn.name}" for fn in funcs
            if not fn.name.startswith("_") and fn.name not in POSITIONAL_PROTOCOL
            and len([a for a in fn.args.posonlyargs + fn.args.args
                     if a.arg not in ("self", "cls")]) > 3]


def test_options_are_given_by_keyword():
    """No public function takes more than three arguments by position: two options
    swapped by a caller raise a TypeError rather than run with each other's values."""
    assert [m for f in _modules(PACKAGE) + _modules(ROOT / "solver")
            for m in _long_positional(f)] == []


MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 60


def _long_functions(path: Path) -> list[str]:
    """The functions and methods of ``path`` (nested ones too) over MAX_FUNCTION_LINES,
    their docstrings counted."""
    return [f"{path.name}:{node.lineno} {node.name} {node.end_lineno - node.lineno + 1}"
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]


def test_modules_and_functions_stay_small():
    """A module holds one idea a reader takes in at once (at most 400 lines), a function
    one step (at most 60)."""
    modules = _modules(PACKAGE) + _modules(ROOT / "solver")
    assert [(p.relative_to(ROOT).as_posix(), n) for p in modules
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES] == []
    assert [m for p in modules for m in _long_functions(p)] == []


def test_the_checks_above_can_fail(tmp_path):
    # the import reader sees a lazy import, and the flag pattern a flag in an f-string
    f = tmp_path / "m.py"
    f.write_text("def g():\n    from mirrorsim.truth import optics\n"
                 "    raise ValueError(f'--steps {1}')\n")
    assert "mirrorsim.truth.optics" in _imports(f)
    consts = [c.value for c in ast.walk(ast.parse(f.read_text()))
              if isinstance(c, ast.Constant) and isinstance(c.value, str)]
    assert any(FLAG.search(c) for c in consts)
    # the call reader sees a facing derived through a module, and a composer called
    f.write_text("from mirrorsim.truth import optics\n"
                 "def g(s):\n    return optics.target_facing(1, 2, 3), compose_scene(s)\n")
    assert {"target_facing", "compose_scene"} <= _calls(f)
    # the positional count sees a fourth argument, and not one after the star
    f.write_text("def g(a, b, c, d):\n    pass\n\n\ndef h(a, b, c, *, d):\n    pass\n")
    assert [m.split()[1] for m in _long_positional(f)] == ["g"]
    # the size check sees a nested function over the limit
    f.write_text("def g():\n    def h():\n" + "        x = 1\n" * MAX_FUNCTION_LINES
                 + "    return h\n")
    assert [m.split()[1] for m in _long_functions(f)] == ["g", "h"]


def _unannotated(path: Path) -> list[str]:
    """Public functions and methods of ``path`` with a parameter or the return unhinted."""
    out = []
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            funcs = [m for m in node.body if isinstance(m, ast.FunctionDef)]
        else:
            funcs = [node] if isinstance(node, ast.FunctionDef) else []
        for fn in funcs:
            if fn.name.startswith("_"):
                continue
            args = [a for a in fn.args.args + fn.args.kwonlyargs if a.arg not in ("self", "cls")]
            if fn.returns is None or any(a.annotation is None for a in args):
                out.append(f"{path}:{fn.lineno} {fn.name}")
    return out


def test_every_public_function_is_hinted(tmp_path):
    """Typed values between modules: each public function says what it takes and gives."""
    missing = [m for f in _modules(PACKAGE) + _modules(ROOT / "solver") for m in _unannotated(f)]
    assert not missing, missing
    # and the reader finds one that is not
    f = tmp_path / "m.py"
    f.write_text("def g(x) -> int:\n    return x\n\n\nclass C:\n    def h(self, y: int):\n"
                 "        return y\n")
    assert [m.split()[-1] for m in _unannotated(f)] == ["g", "h"]


def test_the_command_lines_help_imports_no_numeric_library():
    # `mirrorsim --help` builds every command's parser without its options: it needs
    # neither NumPy nor Mitsuba (an error model imported for a type hint had brought
    # NumPy in, 0.06 → 0.19 s)
    loaded = _loaded_by("mirrorsim.cli.main")
    assert not {"numpy", "mitsuba", "drjit", "scipy", "pandas", "cv2"} & loaded
