"""A hostile harness: cases a careless script or a new user would try, by class.

Each case returns ``""`` where mirrorsim behaves as documented (one line, the right exit
status, nothing half-written, the damage found) and a short description of what went
wrong otherwise.  ``tests/test_hostile.py`` runs every case (the cheap ones in the fast
suite); ``benchmarks/hostile.py`` counts them per class.

Classes:

* ``belongs``: every file in a folder checked against what it belongs to (a swapped
  table, damaged or missing frames, a capture record of another frame);
* ``api``: every public function's arguments checked before any work (None, a wrong
  type, NaN, a bool for a number, a string for a bool), numpy scalars taken;
* ``before-out``: bad input refused before the output folder is claimed;
* ``exit``: a full disk or a file-size limit is a failed run (exit 1, one line naming
  the cause); bad input stays exit 2;
* ``bounds``: seeds, counts and comma lists bounded and refused in one line.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import os
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenes" / "default.yaml"
SPEC = ROOT / "tests" / "data" / "tiny_spec.yaml"
CLASSES = ("belongs", "api", "before-out", "exit", "bounds")


@dataclass(frozen=True)
class Case:
    """One hostile case: its class, a name, whether it is cheap (no render, no dataset)
    and what it runs in a fresh folder (``""``: clean)."""

    cls: str
    name: str
    cheap: bool
    run: Callable[[Path], str]


CASES: list[Case] = []


def case(cls: str, name: str, cheap: bool = True):
    assert cls in CLASSES

    def add(fn: Callable[[Path], str]) -> Callable[[Path], str]:
        CASES.append(Case(cls, name, cheap, fn))
        return fn
    return add


# ------------------------------------------------------------------------ helpers


def cli(argv: list[str]) -> tuple[int, str, str]:
    """``mirrorsim ARGV`` in this process: (status, stdout, stderr)."""
    from mirrorsim.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            warnings.catch_warnings():
        warnings.simplefilter("default")  # shown as the command shows them, never raised
        try:
            status = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse
            status = int(exc.code or 0)
        except Exception as exc:  # a traceback reaching the user  # noqa: BLE001
            return -1, out.getvalue(), f"{type(exc).__name__}: {exc}"
    return status, out.getvalue(), err.getvalue()


def shell(command: str, cwd: Path) -> tuple[int, str]:
    """A shell command (for ``ulimit``): (status, stderr)."""
    env_python = Path(sys.executable).parent
    # this checkout's mirrorsim, whichever one the environment installed
    done = subprocess.run(["bash", "-c", f"PATH={env_python}:$PATH; {command}"], cwd=cwd,
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    return done.returncode, done.stderr


def refused(result: tuple[int, str, str], status: int = 2, says: tuple[str, ...] = ()
            ) -> str:
    """"" if the run exited ``status`` with one ``error:`` line saying each of ``says``."""
    got, _, err = result
    lines = [ln for ln in err.splitlines() if not ln.startswith("warning:")]
    if got != status:
        return f"exit {got} (wanted {status}): {err.strip()[-160:]!r}"
    if len(lines) != 1 or not lines[0].startswith("error:"):
        return f"not one error line: {err.strip()[-160:]!r}"
    missing = [s for s in says if s.lower() not in lines[0].lower()]
    return f"the line does not say {missing}: {lines[0]!r}" if missing else ""


def absent(path: Path) -> str:
    return f"{path.name} was left behind" if path.exists() else ""


def first(*checks: str) -> str:
    return next((c for c in checks if c), "")


def scene_file(tmp: Path, name: str = "s", width: int = 320, **changes) -> Path:
    """The default scene ``width`` px wide (same geometry), with ``changes`` (dotted
    keys).  320 px: nothing is measured (a case that renders is no longer clean)."""
    d = yaml.safe_load(DEFAULT.read_text())
    d["name"] = name
    d["camera"]["resolution"] = [width, round(width * 1088 / 1920 / 2) * 2]
    for key, value in changes.items():
        node = d
        *path, last = key.split(".")
        for k in path:
            node = node.setdefault(k, {})
        node[last] = value
    p = tmp / f"{name}.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def nan_model(tmp: Path) -> Path:
    """The shipped ideal model's file with one σ made NaN (a bad model)."""
    from mirrorsim.formats.error_model import default_model_path

    d = json.loads(default_model_path("ideal").read_text())
    d["shared_alpha_deg"] = math.nan
    p = tmp / "nan-model.json"
    p.write_text(json.dumps(d))
    return p


# ------------------------------------------------------------------------ before-out

for _cmd in ("evaluate", "budget", "track"):
    for _what, _make in (("a NaN model", nan_model),
                         ("a folder", lambda t: t),
                         ("/dev/zero", lambda _t: Path("/dev/zero"))):
        @case("before-out", f"{_cmd} --error-model {_what}: OUT not made")
        def _bad_model(tmp, cmd=_cmd, make=_make):
            out = tmp / "out"
            return first(refused(cli([cmd, scene_file(tmp), "--out", out,
                                      "--error-model", make(tmp), "--quiet"])), absent(out))

for _what, _make in (("a NaN model", nan_model), ("a folder", lambda t: t)):
    @case("before-out", f"dataset --error-model {_what}: OUT not made")
    def _bad_dataset_model(tmp, make=_make):
        out = tmp / "out"
        return first(refused(cli(["dataset", "--n", 2, "--seed", 1, "--out", out, "--spec",
                                  SPEC, "--error-model", make(tmp), "--quiet"])), absent(out))


@case("before-out", "evaluate --board-pose on a plain board: OUT not made")
def _board_plain(tmp):
    out = tmp / "out"
    return first(refused(cli(["evaluate", scene_file(tmp, **{"board.hole_pitch": 0}),
                              "--out", out, "--board-pose", "--quiet"]),
                         says=("--board-pose",)), absent(out))


@case("before-out", "evaluate --calibrate bogus: OUT not made")
def _calibrate_bogus(tmp):
    out = tmp / "out"
    return first(refused(cli(["evaluate", scene_file(tmp), "--out", out, "--calibrate",
                              "bogus"])), absent(out))


@case("before-out", "evaluate --prior pan=-1: OUT not made")
def _prior_negative(tmp):
    out = tmp / "out"
    return first(refused(cli(["evaluate", scene_file(tmp), "--out", out, "--calibrate",
                              "pan", "--prior", "pan=-1"])), absent(out))


@case("before-out", "budget --calibrate scale on one beacon: OUT not made")
def _budget_too_many(tmp):
    out = tmp / "out"
    return first(refused(cli(["budget", scene_file(tmp), "--out", out, "--calibrate",
                              "pan,scale,power"])), absent(out))


@case("before-out", "track --steps 0: OUT not made")
def _track_steps(tmp):
    out = tmp / "out"
    return first(refused(cli(["track", scene_file(tmp), "--out", out, "--steps", 0])),
                 absent(out))


@case("before-out", "dataset --spec missing: OUT not made")
def _dataset_spec_missing(tmp):
    out = tmp / "out"
    return first(refused(cli(["dataset", "--n", 2, "--seed", 1, "--out", out, "--spec",
                              tmp / "nope.yaml"])), absent(out))


@case("before-out", "ms.evaluate(error_model='x.json'): out not made")
def _api_model_path(tmp):
    import mirrorsim as ms

    out = tmp / "out"
    return first(_raises(lambda: ms.evaluate(ms.load_scene(scene_file(tmp)), out,
                                             error_model="x.json"), "error_model"),
                 absent(out))


@case("before-out", "ms.generate_dataset(n=0): out not made")
def _api_dataset_n0(tmp):
    import mirrorsim as ms

    out = tmp / "out"
    return first(_raises(lambda: ms.generate_dataset(0, 1, out), "n"), absent(out))


@case("before-out", "ms.render(scene, out, variant='bogus'): out not made")
def _api_render_variant(tmp):
    import mirrorsim as ms

    out = tmp / "out"
    return first(_raises(lambda: ms.render(ms.load_scene(scene_file(tmp)), out,
                                           variant="bogus"), "variant"), absent(out))


@case("before-out", "ms.evaluate(keep=('bogus',)): out not made")
def _api_keep(tmp):
    import mirrorsim as ms

    out = tmp / "out"
    return first(_raises(lambda: ms.evaluate(ms.load_scene(scene_file(tmp)), out,
                                             keep=("bogus",)), "keep"), absent(out))


@case("before-out", "ms.track(steps=0): out not made")
def _api_track_steps(tmp):
    import mirrorsim as ms

    out = tmp / "out"
    return first(_raises(lambda: ms.track(ms.load_scene(scene_file(tmp)), out, steps=0),
                         "steps"), absent(out))


# ------------------------------------------------------------------------ exit


def _limited(tmp: Path, argv: str, blocks: int = 32) -> str:
    """``mirrorsim ARGV`` under ``ulimit -f BLOCKS`` (KiB): a failed run, exit 1, one
    line naming the limit."""
    status, err = shell(f"ulimit -f {blocks}; mirrorsim {argv}", tmp)
    lines = [ln for ln in err.splitlines() if not ln.startswith("warning:")]
    if status != 1:
        return f"exit {status} (wanted 1): {err.strip()[-160:]!r}"
    if len(lines) != 1 or not any(w in lines[0] for w in ("file size limit", "disk full")):
        return f"not one line naming the cause: {err.strip()[-160:]!r}"
    return ""


@case("exit", "evaluate under a 32 KiB file-size limit: exit 1")
def _exit_evaluate(tmp):
    return _limited(tmp, f"evaluate {scene_file(tmp)} --out out --quiet")


@case("exit", "render under a 32 KiB file-size limit: exit 1")
def _exit_render(tmp):
    return _limited(tmp, f"render {scene_file(tmp)} --out out --quiet")


@case("exit", "dataset under a 32 KiB file-size limit: exit 1")
def _exit_dataset(tmp):
    return _limited(tmp, f"dataset --n 2 --seed 1 --spec {SPEC} --out out --quiet")


@case("exit", "plot under a 32 KiB file-size limit: exit 1")
def _exit_plot(tmp):
    return _limited(tmp, f"plot {scene_file(tmp)} --out top.png")


@case("exit", "check --json under a 1 KiB file-size limit: exit 1")
def _exit_check_json(tmp):
    return _limited(tmp, f"check {scene_file(tmp)} --json truth.json", blocks=1)


@case("exit", "plan --out under a 1 KiB file-size limit: exit 1")
def _exit_plan(tmp):
    return _limited(tmp, f"plan {scene_file(tmp)} --out planned.yaml", blocks=1)


@case("exit", "a missing scene under a file-size limit is still bad input: exit 2")
def _exit_still_input(tmp):
    status, err = shell("ulimit -f 32; mirrorsim evaluate nope.yaml --out out --quiet", tmp)
    return "" if status == 2 and err.count("\n") == 1 else f"exit {status}: {err[-160:]!r}"


@case("exit", "an output on a read-only file system is bad input: exit 2")
def _exit_readonly(tmp):
    return refused(cli(["check", scene_file(tmp), "--json", "/proc/x.json"]))


# ------------------------------------------------------------------------ bounds

BIG = str(2**70)
for _argv, _says in (
        (["dataset", "--n", 2, "--seed", BIG], ("--seed",)),
        (["dataset", "--n", 2, "--seed", -1], ("--seed",)),
        (["dataset", "--n", 10**7, "--seed", 1], ("--n",)),
        (["dataset", "--n", BIG, "--seed", 1], ("--n",)),
        (["dataset", "--n", 2, "--seed", 1, "--workers", 10**6], ("--workers",)),
        (["dataset", "--n", 2, "--seed", 1, "--workers", BIG], ("--workers",)),
        (["dataset", "--n", 2, "--seed", 1, "--calibrate", ""], ("--calibrate",)),
        (["dataset", "--n", 2, "--seed", 1, "--calibrate", ","], ("--calibrate",)),
        (["dataset", "--n", 2, "--seed", 1, "--beacons", 3, "--calibrate", "pan,"],
         ("--calibrate",)),
        (["dataset", "--n", 2, "--seed", 1, "--beacons", 3, "--calibrate", "pan,,scale"],
         ("--calibrate",)),
        (["dataset", "--n", 2, "--seed", 1, "--beacons", BIG], ("--beacons",)),
        (["evaluate", "{scene}", "--calibrate", ""], ("--calibrate",)),
        (["evaluate", "{scene}", "--calibrate", " , "], ("--calibrate",)),
        (["evaluate", "{scene}", "--calibrate", "pan", "--prior", "pan=0.3,"], ("--prior",)),
        (["evaluate", "{scene}", "--seed", BIG], ("--seed",)),
        (["evaluate", "{scene}", "--spp", BIG], ("--spp",)),
        (["track", "{scene}", "--seed", BIG], ("--seed",)),
        (["track", "{scene}", "--steps", BIG], ("--steps",)),
        (["montecarlo", "--seed", BIG], ("--seed",)),
        (["montecarlo", "--iterations", BIG], ("--iterations",)),
        (["plan", "{scene}", "--beacons", BIG], ("--beacons",)),
        (["render", "{scene}", "--seed", BIG], ("--seed",)),
):
    @case("bounds", " ".join(str(a) for a in _argv)[:70])
    def _bound(tmp, argv=_argv, says=_says):
        out = tmp / "out"
        argv = [str(scene_file(tmp)) if a == "{scene}" else a for a in argv]
        if argv[0] in ("dataset", "evaluate", "track", "render"):
            argv = [*argv, "--out", out]
        return first(refused(cli(argv), says=says), absent(out))


def _dataset_json(tmp: Path, **edits) -> Path:
    """A folder whose dataset.json (as ``mirrorsim dataset`` writes it) has ``edits``."""
    out = tmp / "ds"
    out.mkdir()
    spec = yaml.safe_load(SPEC.read_text())
    meta = {"format": "mirrorsim-dataset", "n": 2, "seed": 1, "spp": None, "spec": spec}
    meta.update(edits)
    (out / "dataset.json").write_text(json.dumps(meta))
    return out


for _key, _value in (("n", "8"), ("seed", "1"), ("n", 2.5), ("n", None), ("seed", [1])):
    @case("bounds", f"dataset --resume with dataset.json {_key}: {_value!r}")
    def _json_type(tmp, key=_key, value=_value):
        out = _dataset_json(tmp, **{key: value})
        return refused(cli(["dataset", "--n", 8, "--seed", 1, "--spec", SPEC, "--out", out,
                            "--resume", "--quiet"]), says=(key,))


@case("bounds", "ms.generate_dataset(seed=2**70)")
def _api_seed(tmp):
    import mirrorsim as ms

    return first(_raises(lambda: ms.generate_dataset(2, 2**70, tmp / "out"), "seed"),
                 absent(tmp / "out"))


@case("bounds", "ms.track(seed=2**70)")
def _api_track_seed(tmp):
    import mirrorsim as ms

    return first(_raises(lambda: ms.track(ms.load_scene(scene_file(tmp)), tmp / "out",
                                          seed=2**70), "seed"), absent(tmp / "out"))


@case("bounds", "ms.SelfCalibration(('pan', ''))")
def _api_empty_nuisance(_tmp):
    import mirrorsim as ms

    return _raises(lambda: ms.SelfCalibration(("pan", "")), "nuisances")


# ------------------------------------------------------------------------ api


def _raises(call: Callable[[], object], parameter: str) -> str:
    """"" if ``call`` raises the library's InputError naming ``parameter``, before work."""
    from mirrorsim.errors import InputError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            call()
    except InputError as exc:
        return "" if parameter in str(exc) else f"InputError not naming {parameter}: {exc}"
    except Exception as exc:  # noqa: BLE001
        return f"{type(exc).__name__}: {str(exc)[:120]}"
    return "accepted"


def _base_arguments(tmp: Path) -> dict[str, dict]:
    """Valid arguments of each public name (the hostile value replaces one of them)."""
    import mirrorsim as ms

    scene = ms.load_scene(scene_file(tmp))
    out = tmp / "out"
    return {
        "load_scene": {"path": scene_file(tmp)},
        "edit_scene": {"scene": scene, "changes": {"target.position": [57, 51]}},
        "check": {"scene": scene},
        "render": {"scene": scene, "out": out},
        "load_capture": {"path": tmp / "c.capture.json"},
        "detect": {"image_path": tmp / "f.png", "capture": tmp / "c.capture.json"},
        "solve": {"observer": (0.0, 0.0),
                  "beacons": [ms.BeaconMeasurement((36.0, 56.0), 30.0, 60.0)],
                  "targets": [(30.0, 60.0)]},
        "BeaconMeasurement": {"position": (36.0, 56.0), "alpha_deg": 30.0, "d_total": 60.0},
        "load_measurements": {"path": tmp / "m.json"},
        "SelfCalibration": {"nuisances": ("pan",), "position_sigma": 0.0},
        "evaluate": {"scene": scene, "out_dir": out},
        "budget": {"scene": scene, "out": out},
        "track": {"scene": scene, "out": out},
        "plan": {"scene": scene},
        "generate_dataset": {"n": 2, "seed": 1, "out": out},
        "load_dataset": {"folder": tmp / "ds"},
        "fit_error_model": {"dataset_dir": tmp / "ds"},
        "load_error_model": {"path": None},
        "model_for": {"scene": scene},
    }


# what each kind of parameter must refuse: (label, value)
_NONE = ("None", None)
_WRONG = ("a wrong type", object())
_NAN = ("NaN", math.nan)
_BOOL = ("a bool for a number", True)
_STR_FOR_BOOL = ("a string for a bool", "no")
# per public name, per parameter, the hostile values (by what the parameter takes)
_HOSTILE = {
    "load_scene": {"path": (_NONE, ("an int", 5), ("bytes", b"x"))},
    "edit_scene": {"scene": (_NONE, ("a path", "scenes/default.yaml")),
                   "changes": (_NONE, ("a list", [1]))},
    "check": {"scene": (_NONE, ("a dict", {}))},
    "render": {"scene": (_NONE,), "out": (("an int", 5),), "progress": (_STR_FOR_BOOL,),
               "reuse": (_STR_FOR_BOOL,), "ids": (_STR_FOR_BOOL,), "variant": (("an int", 1),)},
    "load_capture": {"path": (_NONE, ("an int", 5))},
    "detect": {"image_path": (_NONE, ("an int", 5)), "capture": (_NONE, ("an int", 5)),
               "distance_error": (_NAN, _BOOL, ("a string", "1"))},
    "solve": {"observer": (_NONE, ("a string", "0,0"), ("NaN in it", (math.nan, 0.0))),
              "beacons": (_NONE, ("a measurement, not a list", "b")),
              "targets": (_NONE,), "calibration": (("a tuple", ("pan",)),)},
    "BeaconMeasurement": {"position": (_NONE,), "alpha_deg": (_NAN, _BOOL, ("a string", "1")),
                          "d_total": (_NAN, _BOOL, _NONE)},
    "load_measurements": {"path": (_NONE, ("an int", 5))},
    "SelfCalibration": {"nuisances": (("a string", "pan"), _NONE),
                        "position_sigma": (_NAN, _BOOL, ("a string", "0.1"))},
    "evaluate": {"scene": (_NONE, ("a path", "scenes/default.yaml")),
                 "out_dir": (("an int", 5),), "progress": (_STR_FOR_BOOL,),
                 "error_model": (("a path", "x.json"),),
                 "keep": (("a string", "ids"),), "board_pose": (_STR_FOR_BOOL, ("an int", 1)),
                 "calibration": (("a tuple", ("pan",)),)},
    "budget": {"scene": (_NONE,), "out": (_NONE, ("an int", 5)),
               "progress": (_STR_FOR_BOOL,), "keep": (("a string", "ids"),)},
    "track": {"scene": (_NONE,), "out": (_NONE,), "steps": (_BOOL, ("a float", 2.5), _NAN),
              "odometry_sigma": (_NAN, _BOOL), "seed": (_BOOL, ("a float", 1.0)),
              "side": (_NAN,), "particles": (_BOOL,), "kind": (("an int", 1),)},
    "plan": {"scene": (_NONE,), "eps_deg": (_NAN, _BOOL), "n_beacons": (_BOOL, ("a float", 2.0)),
             "step": (_NAN,)},
    "generate_dataset": {"n": (_BOOL, ("a float", 2.0), _NONE), "seed": (_BOOL, _NONE),
                         "out": (_NONE,), "workers": (_BOOL,), "resume": (_STR_FOR_BOOL,),
                         "beacons": (_BOOL,), "max_rss_mb": (_NAN, _BOOL),
                         "progress": (_STR_FOR_BOOL,)},
    "load_dataset": {"folder": (_NONE, ("an int", 123), ("bytes", b"x"))},
    "fit_error_model": {"dataset_dir": (_NONE, ("an int", 1))},
    "load_error_model": {"path": (("an int", 1),), "kind": (_NONE, ("an int", 1))},
    "model_for": {"scene": (_NONE,), "error_model": (("a path", "m.json"),)},
}

for _name, _params in _HOSTILE.items():
    for _param, _values in _params.items():
        for _label, _value in _values:
            @case("api", f"ms.{_name}({_param}=<{_label}>)")
            def _api(tmp, name=_name, param=_param, value=_value):
                import mirrorsim as ms

                kwargs = {**_base_arguments(tmp)[name], param: copy.copy(value)}
                return first(_raises(lambda: getattr(ms, name)(**kwargs), param),
                             absent(tmp / "out"))

# a numpy scalar where a number is right: taken, and passed on as a plain number
for _name, _param, _value in (("BeaconMeasurement", "alpha_deg", np.float64(30.0)),
                              ("BeaconMeasurement", "d_total", np.float32(60.0)),
                              ("SelfCalibration", "position_sigma", np.float64(0.1))):
    @case("api", f"ms.{_name}({_param}=<numpy {type(_value).__name__}>) taken")
    def _numpy_ok(tmp, name=_name, param=_param, value=_value):
        import mirrorsim as ms

        kwargs = {**_base_arguments(tmp)[name], param: value}
        try:
            made = getattr(ms, name)(**kwargs)
        except Exception as exc:  # noqa: BLE001
            return f"{type(exc).__name__}: {exc}"
        got = getattr(made, param)
        return "" if type(got) is float else f"kept as {type(got).__name__}"


@case("api", "ms.plan(n_beacons=np.int64(1), step=np.float32(2)) taken")
def _numpy_plan(tmp):
    import mirrorsim as ms

    scene = ms.load_scene(scene_file(tmp))
    try:
        ms.plan(scene, n_beacons=np.int64(1), step=np.float32(2.0), n_poses=np.int64(2))
    except Exception as exc:  # noqa: BLE001
        return f"{type(exc).__name__}: {exc}"
    return ""


@case("api", "ms.check(scene) of a scene edited into NaN")
def _api_nan_scene(tmp):
    import mirrorsim as ms

    scene = ms.load_scene(scene_file(tmp))
    return _raises(lambda: ms.edit_scene(scene, {"mirror.yaw": math.nan}), "mirror.yaw")


# ------------------------------------------------------------------------ belongs
# (a two-scene dataset and a two-beacon frame are made once: not cheap)

_MADE: dict[str, Path] = {}


def _dataset(tmp: Path, seed: int = 3) -> Path:
    """A copy of a finished two-scene dataset of ``seed`` (made once per process)."""
    key = f"ds{seed}"
    if key not in _MADE:
        import mirrorsim as ms

        made = Path(_MADE.setdefault("root", Path(_tmpdir()))) / key
        spec = _small_spec(made.parent)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ms.generate_dataset(2, seed, made, spec_path=spec, progress=False)
        _MADE[key] = made
    copy_to = tmp / f"ds{seed}"
    shutil.copytree(_MADE[key], copy_to)
    return copy_to


def _tmpdir() -> str:
    import tempfile

    return tempfile.mkdtemp(prefix="mirrorsim-hostile-")


def _small_spec(folder: Path) -> Path:
    spec = yaml.safe_load(SPEC.read_text())  # 960×544: every scene measured
    p = folder / "small_spec.yaml"
    p.write_text(yaml.safe_dump(spec))
    return p


def _frame(ds: Path, i: int = 0) -> Path:
    return next((ds / "frames" / f"scene{i:06d}").glob("scene*.png"))


@case("belongs", "a dataset's table swapped for another's of the same size", cheap=False)
def _swapped_table(tmp):
    import mirrorsim as ms

    ds, other = _dataset(tmp, 3), _dataset(tmp, 4)
    shutil.copy(other / "dataset.parquet", ds / "dataset.parquet")
    return first(refused(cli(["errormodel", ds, "--out", tmp / "m.json"])),
                 _raises(lambda: ms.load_dataset(ds), "dataset.parquet"))


@case("belongs", "dataset --resume redoes a truncated frame", cheap=False)
def _resume_truncated(tmp):
    ds = _dataset(tmp)
    frame = _frame(ds)
    good = frame.read_bytes()
    frame.write_bytes(good[: len(good) // 2])
    status, _, err = cli(["dataset", "--n", 2, "--seed", 3, "--out", ds, "--spec",
                          _small_spec(tmp), "--resume", "--quiet"])
    return _redone(ds, status, err, frame, good)


def _redone(ds: Path, status: int, err: str, frame: Path, good: bytes) -> str:
    """"" if a resume exited 0 and left a dataset whose every file verifies again (the
    scene redone: its frame rendered anew from the same seed)."""
    import mirrorsim as ms

    if status != 0:
        return f"exit {status}: {err[-160:]!r}"
    if "redone" not in err:
        return f"no warning that the scene is redone ({err[-160:]!r})"
    try:
        ms.load_dataset(ds)
    except Exception as exc:  # noqa: BLE001
        return f"after the resume: {type(exc).__name__}: {exc}"
    # rendered anew from the same seed: the same bytes as before it was damaged
    return "" if frame.read_bytes() == good else "the frame was not redone as it was"


@case("belongs", "dataset --resume redoes a frame swapped with another scene's", cheap=False)
def _resume_swapped(tmp):
    ds = _dataset(tmp)
    a, b = _frame(ds, 0), _frame(ds, 1)
    good = a.read_bytes()
    shutil.copy(b, a)
    status, _, err = cli(["dataset", "--n", 2, "--seed", 3, "--out", ds, "--spec",
                          _small_spec(tmp), "--resume", "--quiet"])
    return _redone(ds, status, err, a, good)


@case("belongs", "ms.load_dataset with a truncated frame", cheap=False)
def _load_truncated(tmp):
    import mirrorsim as ms

    ds = _dataset(tmp)
    frame = _frame(ds, 1)
    frame.write_bytes(frame.read_bytes()[:100])
    return _raises(lambda: ms.load_dataset(ds), frame.name)


@case("belongs", "ms.load_dataset with a measurements file of another scene", cheap=False)
def _load_swapped_measurements(tmp):
    import mirrorsim as ms

    ds = _dataset(tmp)
    a = ds / "frames" / "scene000000" / "scene000000.measurements.json"
    b = ds / "frames" / "scene000001" / "scene000001.measurements.json"
    shutil.copy(b, a)
    return _raises(lambda: ms.load_dataset(ds), a.name)


@case("belongs", "ms.load_dataset with frames/ removed names the missing frames",
      cheap=False)
def _load_no_frames(tmp):
    import mirrorsim as ms

    ds = _dataset(tmp)
    shutil.rmtree(ds / "frames")
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        try:
            df = ms.load_dataset(ds)
        except Exception as exc:  # noqa: BLE001
            return f"{type(exc).__name__}: {exc}"
    said = " ".join(str(w.message) for w in seen)
    if "scene000000" not in said or "missing" not in said:
        return f"no warning naming the missing frames ({said[:120]!r})"
    # a file missing from a scene that did not fail reads None ('' is a failed scene's)
    kept = [f for f, e in zip(df["frame"], df["error"], strict=True) if not e]
    return "" if kept and all(f is None for f in kept) else f"missing frames read as {kept[:2]!r}"


@case("belongs", "errormodel with a damaged frame", cheap=False)
def _errormodel_damaged(tmp):
    ds = _dataset(tmp)
    frame = _frame(ds, 0)
    frame.write_bytes(frame.read_bytes()[:-10])
    return refused(cli(["errormodel", ds, "--out", tmp / "m.json"]), says=(frame.name,))


@case("belongs", "errormodel with a truth file of another scene", cheap=False)
def _errormodel_truth(tmp):
    ds = _dataset(tmp)
    a = ds / "frames" / "scene000000" / "scene000000.json"
    shutil.copy(ds / "frames" / "scene000001" / "scene000001.json", a)
    return refused(cli(["errormodel", ds, "--out", tmp / "m.json"]), says=(a.name,))


def _two_beacon_frames(tmp: Path) -> Path:
    """A two-beacon scene rendered small (once per process): its folder, copied."""
    if "two" not in _MADE:
        import mirrorsim as ms

        root = Path(_MADE.setdefault("root", Path(_tmpdir())))
        src = scene_file(root, "two", width=960, beacons=[{"position": [36, 56], "height": 4.2},
                                               {"position": [24, 58], "height": 4.2}])
        d = yaml.safe_load(src.read_text())
        d.pop("beacon")
        src.write_text(yaml.safe_dump(d))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ms.evaluate(ms.load_scene(src), root / "two", progress=False, keep=())
        _MADE["two"] = root / "two"
    shutil.copytree(_MADE["two"], tmp / "two")
    return tmp / "two"


@case("belongs", "detect FRAME --capture of the scene's other beacon's frame", cheap=False)
def _detect_other_capture(tmp):
    two = _two_beacon_frames(tmp)
    return refused(cli(["detect", two / "two_b0.png", "--capture",
                        two / "two_b1.capture.json"]), says=("two_b1.capture.json",))


@case("belongs", "ms.detect(frame, capture of another frame)", cheap=False)
def _api_detect_other_capture(tmp):
    import mirrorsim as ms

    two = _two_beacon_frames(tmp)
    return _raises(lambda: ms.detect(two / "two_b1.png", two / "two_b0.capture.json"),
                   "capture")


@case("belongs", "detect FRAME --capture of its own frame is taken", cheap=False)
def _detect_own_capture(tmp):
    two = _two_beacon_frames(tmp)
    status, _, err = cli(["detect", two / "two_b1.png", "--capture",
                          two / "two_b1.capture.json"])
    return "" if status == 0 else f"exit {status}: {err[-160:]!r}"


@case("belongs", "detect a frame renamed, with its own capture record", cheap=False)
def _detect_renamed(tmp):
    two = _two_beacon_frames(tmp)
    shutil.copy(two / "two_b0.png", tmp / "renamed.png")
    status, _, err = cli(["detect", tmp / "renamed.png", "--capture",
                          two / "two_b0.capture.json"])
    return "" if status == 0 else f"exit {status}: {err[-160:]!r}"


def run(cases: list[Case], root: Path) -> dict[str, list[tuple[str, str]]]:
    """Run ``cases`` each in a fresh folder under ``root``: class → [(name, verdict)]."""
    results: dict[str, list[tuple[str, str]]] = {c: [] for c in CLASSES}
    for k, c in enumerate(cases):
        tmp = root / f"case{k:03d}"
        tmp.mkdir(parents=True)
        try:
            verdict = c.run(tmp)
        except Exception as exc:  # noqa: BLE001
            verdict = f"the harness raised {type(exc).__name__}: {exc}"
        results[c.cls].append((c.name, verdict))
    return results
