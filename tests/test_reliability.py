"""Bad input and interruption, by class (issue 10): each class with cases of its own.

Every bad input must give exit 2, one line on stderr naming what is wrong, no
traceback and nothing written; interruptions must stop at once and lose, double or
corrupt nothing.
"""

import copy
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from mirrorsim.cli.main import main
from mirrorsim.formats import files as io

from .conftest import ROOT, SCENES, scene_dict

SPEC = ROOT / "tests" / "data" / "tiny_spec.yaml"
DEFAULT = str(SCENES / "default.yaml")


def _refused(capsys, argv, *, status=2, says=()) -> str:
    """Run the CLI; assert the status and a single clean stderr line; return that line."""
    assert main(argv) == status
    err = capsys.readouterr().err.strip().splitlines()
    errors = [ln for ln in err if ln.startswith("error: ")]
    assert len(errors) == 1 and "Traceback" not in "\n".join(err), err
    for word in says:
        assert word in errors[0], errors[0]
    return errors[0]


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")} if folder.exists() else set()


# ------------------------------------------------------------ 1. interruptions


def test_ctrl_c_during_dataset_stops_at_once_and_resume_is_exact(tmp_path):
    """Ctrl-C to the whole process group (as a terminal sends it) with two workers busy:
    the run stops within seconds, no worker survives, no row is half-written or
    recorded as a failure, and --resume gives the rows of an uninterrupted run."""
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "mirrorsim", "dataset", "--n", "4", "--seed", "11",
           "--out", str(out), "--spec", str(SPEC), "--workers", "2", "--quiet"]
    # SIGINT as a terminal's foreground job has it: a shell's background job (CI started
    # with `&`) ignores it, and an ignored signal stays ignored across exec
    proc = subprocess.Popen(cmd, start_new_session=True, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 120
    while time.time() < deadline and not list((out / "rows").glob("scene*.json")):
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)
    t0 = time.time()
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "interrupted" in err
    assert time.time() - t0 < 20  # "within a few seconds": generous for a slow machine
    # nothing of that session is left running (multiprocessing's resource tracker may
    # take a moment to see its parent gone)
    while time.time() - t0 < 30:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    else:
        raise AssertionError("a process of the interrupted run is still alive")
    rows = [json.loads(p.read_text()) for p in sorted((out / "rows").glob("scene*.json"))]
    assert 1 <= len(rows) < 4 and all(r["error"] == "" for r in rows)
    assert subprocess.run(cmd + ["--resume"], capture_output=True).returncode == 0
    ref = tmp_path / "ref"
    assert main(["dataset", "--n", "4", "--seed", "11", "--out", str(ref), "--spec", str(SPEC),
                 "--workers", "1", "--quiet"]) == 0
    # the seal covers the timings, and the files' digests the truth files' timings
    volatile = {"seconds_total", "seconds_sample", "sha256", "files"}

    def rows_of(folder):
        return [{k: v for k, v in json.loads(p.read_text()).items() if k not in volatile}
                for p in sorted((folder / "rows").glob("scene*.json"))]

    def frames_of(folder):  # the frames' digests each row recorded: the same pixels
        return [{k: v for k, v in json.loads(p.read_text())["files"].items()
                 if k.endswith(".png")} for p in sorted((folder / "rows").glob("scene*.json"))]

    assert rows_of(out) == rows_of(ref) and len(rows_of(ref)) == 4
    assert frames_of(out) == frames_of(ref)
    assert all(r["error"] == "" for r in rows_of(ref))


@pytest.mark.parametrize("exc, recorded", [
    (MemoryError("out of memory"), False),  # outside the scene: redone on resume
    (OSError(28, "No space left on device"), False),
    ("detection", True),  # the scene's own: a row with its error
])
def test_only_the_scenes_own_failures_become_rows(tmp_path, monkeypatch, exc, recorded):
    from mirrorsim.errors import DetectionError
    from mirrorsim.pipelines import dataset, evaluate
    from mirrorsim.pipelines.random_scenes import load_spec

    def failing(*_args, **_kwargs):
        raise DetectionError("nothing found") if exc == "detection" else exc

    monkeypatch.setattr(evaluate, "evaluate_into", failing)
    for sub in ("scenes", "rows", "frames"):
        (tmp_path / sub).mkdir()
    result = dataset.process_one(0, 1, load_spec(SPEC), out=str(tmp_path), spp=1,
                                 variant="scalar_rgb")
    assert (tmp_path / "rows" / "scene000000.json").exists() == recorded
    assert (result.row is None) != recorded and bool(result.retry) != recorded
    if recorded:
        assert result.row.error.startswith("DetectionError") and result.row.traceback


# ------------------------------------------------------- 2. other people's files


def test_dataset_never_writes_into_a_folder_of_other_files(tmp_path, capsys):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("my notes")
    before = _files(folder)
    _refused(capsys, ["dataset", "--n", "1", "--seed", "0", "--out", str(folder), "--spec",
                      str(SPEC)], says=("notes.txt", "not a dataset"))
    assert _files(folder) == before and (folder / "notes.txt").read_text() == "my notes"
    # --resume on it is no better, nor on a folder whose dataset.json is someone else's
    _refused(capsys, ["dataset", "--n", "1", "--seed", "0", "--out", str(folder), "--spec",
                      str(SPEC), "--resume"])
    other = tmp_path / "other"
    other.mkdir()
    (other / "dataset.json").write_text('{"name": "not ours"}')
    _refused(capsys, ["dataset", "--n", "1", "--seed", "0", "--out", str(other), "--spec",
                      str(SPEC), "--resume"], says=("not a mirrorsim dataset",))
    (other / "dataset.json").write_text("{broken")
    _refused(capsys, ["dataset", "--n", "1", "--seed", "0", "--out", str(other), "--spec",
                      str(SPEC), "--resume"], says=("dataset.json",))
    # a new folder inside an existing one is fine; --resume where nothing is is not
    _refused(capsys, ["dataset", "--n", "1", "--seed", "0", "--out", str(tmp_path / "new"),
                      "--spec", str(SPEC), "--resume"], says=("no dataset here",))
    assert not (tmp_path / "new").exists()


def test_errormodel_out_must_be_a_json_model(tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "dataset.parquet").write_bytes(b"PAR1 not really")
    for bad in ("model.png", "model"):
        _refused(capsys, ["errormodel", str(ds), "--out", str(ds / bad)], says=("*.json",))
    # the dataset's own table: refused as the run's input, before its suffix is looked at
    _refused(capsys, ["errormodel", str(ds), "--out", str(ds / "dataset.parquet")],
             says=("this run reads it",))
    assert _files(ds) == {"dataset.parquet"}


# ------------------------------------------------------------- 3. output paths


@pytest.mark.parametrize("argv_of", [
    lambda t: ["check", DEFAULT, "--json", str(t / "missing" / "truth.json")],
    lambda t: ["check", DEFAULT, "--measurements", str(t)],  # a folder where a file goes
    lambda _t: ["check", DEFAULT, "--json", "/proc/mirrorsim.json"],  # nothing can be made
    lambda t: ["render", DEFAULT, "--out", str(t / "a" / "b"), "--spp", "1"],
    lambda t: ["evaluate", DEFAULT, "--out", str(t / "file.txt")],  # a file where a folder goes
    lambda t: ["plot", DEFAULT, "--out", str(t / "no" / "top.png")],
    lambda t: ["plan", DEFAULT, "--json", str(t / "no" / "plan.json")],
    lambda t: ["solve", str(t / "m.json"), "--json", "/dev/null"],  # a device: never replaced
    lambda t: ["detect", str(t / "f.png"), "--scene", DEFAULT, "--annotate",
               str(t / "no" / "a.image")],
], ids=["json-missing-parent", "measurements-is-folder", "json-in-proc", "render-out-deep",
        "evaluate-out-is-file", "plot-missing-parent", "plan-json-missing", "solve-json-device",
        "detect-annotate-missing"])
def test_unwritable_outputs_are_refused_before_any_work(tmp_path, capsys, argv_of):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "m.json").write_text(json.dumps({
        "observer": [0, 0], "target": {"alpha_deg": 66.68, "d_total": 98.52},
        "beacons": [{"position": [32, 62.5], "alpha_deg": 69.5, "d_total": 74.7}]}))
    (tmp_path / "f.png").write_bytes(b"not even read")
    before = _files(tmp_path)
    _refused(capsys, argv_of(tmp_path))  # before rendering or detecting: no render folder
    assert _files(tmp_path) == before


def test_a_full_disk_fails_the_run_in_one_line(tmp_path, capsys):
    """A full disk is the machine's failure, not the input's: exit 1, the cause named."""
    full = tmp_path / "full"
    full.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=32k", "tmpfs", str(full)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here (not root?)")
    try:
        line = _refused(capsys, ["check", DEFAULT, "--json", str(full / "truth.json")],
                        status=1)
        assert "disk full" in line and "No space left" in line
        assert list(full.iterdir()) == []
    finally:
        subprocess.run(["umount", str(full)], check=False)


def test_json_is_strict_and_atomic_writes_leave_nothing_on_failure(tmp_path):
    text = io.dumps({"a": math.nan, "b": [math.inf, 1.5], "c": np.float32(2.0)})
    assert json.loads(text) == {"a": None, "b": [None, 1.5], "c": 2.0}
    assert "NaN" not in text and "Infinity" not in text
    target = tmp_path / "x.json"
    with pytest.raises(RuntimeError), io.atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted mid-write")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------- 4. bounds and hangs


@pytest.mark.parametrize("argv, says", [
    (["render", DEFAULT, "--spp", "70000"], "--spp"),
    (["evaluate", DEFAULT, "--spp", "0"], "--spp"),
    (["dataset", "--n", "5000000", "--seed", "0", "--out", "X", "--spec", str(SPEC)], "--n"),
    (["plan", DEFAULT, "--step", "0.2"], "--step"),
    (["montecarlo", "--iterations", "5000000"], "--iterations"),
])
def test_documented_bounds_refused_at_once(tmp_path, capsys, argv, says):
    argv = [str(tmp_path / "o") if a == "X" else a for a in argv]
    _refused(capsys, argv, says=(says,))
    assert not (tmp_path / "o").exists()


def test_a_spec_with_no_valid_scene_says_so_and_stops(tmp_path, capsys):
    spec = yaml.safe_load(SPEC.read_text())
    spec["max_tries"] = 100000
    spec["beacon"]["depth"] = [40, 50]  # far behind the camera's side of the board
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    # refused after its first few hundred draws, not after max_tries = 100000
    _refused(capsys, ["dataset", "--n", "2", "--seed", "0", "--out", str(tmp_path / "o"),
                      "--spec", str(path)], says=("no usable scene in 300 draws", "widen"))
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------ 5. silent nonsense


@pytest.mark.parametrize("edit, key", [
    (lambda s: s["render"].update(spp=-3), "render.spp"),
    (lambda s: s["camera"].update(resolution=[1920]), "camera.resolution"),
    (lambda s: s["camera"].update(pan="left"), "camera.pan"),
    (lambda s: s.update(max_tries=0), "max_tries"),
    (lambda s: s["beacon"].update(height="tall"), "beacon.height"),
    (lambda s: s["target"].update(y=[70, 30]), "target.y"),
    (lambda s: s["occluder"].pop("at"), "occluder.at"),
    (lambda s: s.update(extra=1), "extra"),
    (lambda s: s["render"].update(sampler="sobol"), "render.sampler"),
    (lambda s: s["camera"].update(models=[]), "camera.models"),
    (lambda s: s["camera"].update(models=[{"height": 6, "hfov": 65.2}]), "camera.height"),
    (lambda s: [s["camera"].pop(k) for k in ("height", "hfov")] and s["camera"].update(
        models=[{"height": 6, "hfov": 400}]), "camera.models[0].hfov"),
    (lambda s: [s["camera"].pop(k) for k in ("height", "hfov")] and s["camera"].update(
        models=[{"height": 6, "hfov": 60}, {"hfov": 60}]), "camera.models[1]"),
])
def test_spec_values_that_would_fail_every_scene_are_refused(tmp_path, capsys, edit, key):
    spec = yaml.safe_load(SPEC.read_text())
    edit(spec)
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    _refused(capsys, ["dataset", "--n", "1", "--seed", "0", "--out", str(tmp_path / "o"),
                      "--spec", str(path)], says=(str(path), key))
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("edit, key", [
    (lambda m: m["objects"]["target"]["alpha"].update(typical_sigma=-0.01),
     "objects.target.alpha.typical_sigma"),
    (lambda m: m["objects"]["beacon"]["d_rel"]["log_sigma"].update(scale=[0, 1]),
     "objects.beacon.d_rel.log_sigma.scale"),
    (lambda m: m["objects"]["beacon"]["d_rel"]["log_sigma"].update(intercept=1e300),
     "objects.beacon.d_rel.log_sigma.intercept"),
    (lambda m: m["objects"]["target"].pop("d_rel"), "objects.target.d_rel"),
    (lambda m: m.update(version=1), "version"),
    (lambda m: m.update(sigma={"alpha_deg": 0.01, "d_total_rel": 0.002}), "sigma"),
    # the domain and the tolerances: missing, NaN (strict JSON's null), inconsistent
    (lambda m: m.pop("domain"), "domain"),
    (lambda m: m.pop("tolerances"), "tolerances"),
    (lambda m: m["domain"]["features"]["beacon"].pop("log_noise"),
     "domain.features.beacon.log_noise"),
    (lambda m: m["domain"]["scene"].update(fx_px=[None, 2000]), "domain.scene.fx_px[0]"),
    (lambda m: m["domain"]["scene"].update(fx_px=[2000, 1000]), "domain.scene.fx_px"),
    (lambda m: m["tolerances"].update(pan_deg=None), "tolerances.pan_deg"),
    (lambda m: m["objects"]["target"]["alpha"].update(tail=0.5), "objects.target.alpha.tail"),
    (lambda m: m["objects"]["target"]["alpha"].update(typical_sigma=0.5),
     "objects.target.alpha.typical_sigma"),
    (lambda m: m["domain"]["features"]["target"].update(log_height_px=[7.0, 8.0]),
     "objects.target.alpha.log_sigma.mean"),
    (lambda m: m.update(kind="bench"), "kind"),
    # the target's tail: a scale > 0, a dof > 0 or null
    (lambda m: m.update(target_tail={"scale": 0, "dof": 2.0}), "target_tail.scale"),
    (lambda m: m.update(target_tail={"scale": 0.5, "dof": -1}), "target_tail.dof"),
    (lambda m: m.update(target_tail={"scale": None, "dof": 2.0}), "target_tail.scale"),
    (lambda m: m.update(target_tail={"scale": 0.5}), "target_tail"),
])
def test_error_model_files_are_checked_as_measurement_files_are(tmp_path, capsys, edit, key):
    from mirrorsim.pipelines import errormodel
    from tests.conftest import synthetic_columns

    data = errormodel.fit(synthetic_columns(60, 0)).to_json()
    edit(data)
    model = tmp_path / "model.json"
    model.write_text(json.dumps(data))
    meas = tmp_path / "m.json"
    assert main(["check", str(SCENES / "exp1.yaml"), "--measurements", str(meas)]) == 0
    capsys.readouterr()
    _refused(capsys, ["solve", str(meas), "--error-model", str(model), "--json",
                      str(tmp_path / "s.json")], says=(str(model), key))
    _refused(capsys, ["plan", DEFAULT, "--error-model", str(model)], says=(key,))
    _refused(capsys, ["montecarlo", "--error-model", str(model)], says=(key,))
    assert not (tmp_path / "s.json").exists()
    _refused(capsys, ["evaluate", DEFAULT, "--error-model", str(model), "--out",
                      str(tmp_path / "ev")], says=(str(model), key))
    assert not (tmp_path / "ev").exists()


@pytest.mark.parametrize("argv, says", [
    (["montecarlo", "--incidence", "inf"], "--incidence"),
    (["montecarlo", "--sigma", "nan", "0.1"], "--sigma"),
    (["montecarlo", "--beacon-depth", "-1"], "geometry"),
    (["plan", DEFAULT, "--d1-spread", "-2"], "--d1-spread"),
    (["plan", DEFAULT, "--sigma-d", "200"], "--sigma-d"),
    (["plan", DEFAULT, "--sigma-alpha", "0.01", "--sigma-d", "0"], "--sigma-d"),
])
def test_options_out_of_their_domain_are_refused(capsys, argv, says):
    _refused(capsys, argv, says=(says,))


@pytest.mark.parametrize("edit, key", [
    (lambda m: m.update(target=[]), "target"),
    (lambda m: m.update(sigma={"alpha_deg": 0.01, "d_total_rel": 1e300}), "sigma.d_total_rel"),
    (lambda m: m["beacons"][0].update(position=[1]), "beacons[0].position"),
])
def test_measurement_files_refused_as_bad_input(tmp_path, capsys, edit, key):
    m = {"observer": [0, 0], "target": {"alpha_deg": 66.68, "d_total": 98.52},
         "beacons": [{"position": [32, 62.5], "alpha_deg": 69.5, "d_total": 74.7}]}
    edit(m)
    path = tmp_path / "m.json"
    path.write_text(json.dumps(m))
    _refused(capsys, ["solve", str(path)], says=(str(path), key))


# ------------------------------------------------------ 6. detect on the wrong input


@pytest.fixture(scope="module")
def half_frames(tmp_path_factory):
    """The default scene and EXP3 at half size, rendered once."""
    from mirrorsim.pipelines.frame import render_to_files

    folder = tmp_path_factory.mktemp("frames")
    scenes = {}
    for name in ("default", "exp3"):
        d = copy.deepcopy(scene_dict(name))
        d["camera"]["resolution"] = [960, 544]
        path = folder / f"{name}.yaml"
        path.write_text(yaml.safe_dump(d))
        from mirrorsim.pipelines.scenes import load_scene

        files = render_to_files(load_scene(path).with_render(spp=8), folder / name, progress=False)
        scenes[name] = (path, files.image)
    return folder, scenes


def _detect_process(frame, scene) -> subprocess.CompletedProcess:
    """As a real process, so that C-level noise on stderr (libpng, OpenCV) is seen."""
    return subprocess.run([sys.executable, "-m", "mirrorsim", "detect", str(frame), "--scene",
                           str(scene)], capture_output=True, text=True)


def test_upside_down_and_other_scenes_frames_are_errors_naming_frame_and_scene(half_frames):
    import cv2

    folder, scenes = half_frames
    scene, png = scenes["default"]
    img = cv2.imread(str(png))
    upside = folder / "upside_down.png"
    cv2.imwrite(str(upside), cv2.rotate(img, cv2.ROTATE_180))
    mirrored = folder / "mirrored.png"
    cv2.imwrite(str(mirrored), img[:, ::-1])
    for frame, which in ((upside, scene), (mirrored, scene), (scenes["exp3"][1], scene)):
        proc = _detect_process(frame, which)
        assert proc.returncode == 1, proc.stdout
        lines = proc.stderr.strip().splitlines()
        if frame == scenes["exp3"][1]:  # its own capture record beside it says so first
            assert "records another camera" in lines.pop(0)
        assert len(lines) == 1 and str(frame) in lines[0] and str(which) in lines[0], lines


def test_damaged_frames_give_one_line_and_no_library_noise(half_frames):
    folder, scenes = half_frames
    scene, png = scenes["default"]
    cut = folder / "cut.png"
    cut.write_bytes(png.read_bytes()[:2000])
    text = folder / "notes.png"
    text.write_text("not an image")
    for frame, says in ((cut, "damaged"), (text, "not a PNG or JPEG"),
                        (folder / "absent.png", "no such file")):
        proc = _detect_process(frame, scene)
        assert proc.returncode == 2
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and says in lines[0] and str(frame) in lines[0], lines


def test_a_jpeg_frame_is_measured_with_a_warning(half_frames):
    import cv2

    folder, scenes = half_frames
    scene, png = scenes["default"]
    jpg = folder / "frame.jpg"
    cv2.imwrite(str(jpg), cv2.imread(str(png)), [cv2.IMWRITE_JPEG_QUALITY, 95])
    proc = _detect_process(jpg, scene)
    assert proc.returncode == 0
    assert proc.stderr.startswith("warning: ") and "JPEG" in proc.stderr


def test_an_unwritable_cache_only_costs_a_redo(tmp_path, monkeypatch):
    """The backend probe and calibration caches: a failed write is not an error."""
    from mirrorsim.formats.cache import read_entry, write_entry

    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(io.os, "replace", lambda *_a: (_ for _ in ()).throw(OSError(28, "full")))
    write_entry("calibration", "k", {"k": 1})  # no exception
    assert read_entry("calibration", "k") is None
    assert list((tmp_path / "calibration").iterdir()) == []


# ------------------------------------------- an output never lands on the run's input


def test_an_output_over_the_runs_own_input_is_refused(tmp_path, capsys):
    """`check s.yaml --json s.yaml` would replace the scene with JSON, `errormodel DS
    --out DS/dataset.json` the dataset's description, `solve m.json --json m.json` the
    measurements: each is bad input (exit 2, one line naming the flag), nothing written."""
    import shutil

    from mirrorsim.cli.main import main

    scene = tmp_path / "s.yaml"
    shutil.copy(DEFAULT, scene)
    before = scene.read_bytes()
    assert main(["check", str(scene), "--json", str(scene)]) == 2
    assert main(["check", str(scene), "--measurements", str(tmp_path / "." / "s.yaml")]) == 2
    assert scene.read_bytes() == before
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("this run reads it" in line for line in err)
    assert "--json" in err[0] and "--measurements" in err[1]

    ds = tmp_path / "ds"
    (ds / "rows").mkdir(parents=True)
    (ds / "dataset.json").write_text("{}")
    for out in (ds / "dataset.json", ds / "rows" / "scene000000.json", ds / "README.md"):
        assert main(["errormodel", str(ds), "--out", str(out)]) == 2
    assert (ds / "dataset.json").read_text() == "{}" and not (ds / "README.md").exists()

    meas = tmp_path / "m.json"
    assert main(["check", str(scene), "--measurements", str(meas)]) == 0
    kept = meas.read_bytes()
    assert main(["solve", str(meas), "--json", str(meas)]) == 2
    assert meas.read_bytes() == kept
    # another file beside them is fine
    assert main(["check", str(scene), "--json", str(tmp_path / "truth.json")]) == 0


@pytest.mark.parametrize("argv, says", [
    (["plan", DEFAULT, "--beacons", "2.5"], "--beacons"),  # argparse's, after its usage
    (["track", DEFAULT, "--steps", "0.5"], "--steps"),
    (["montecarlo", "--seed", "-1"], "--seed"),  # a traceback
    (["montecarlo", "--d-total", "1e300"], "--d-total"),  # rows of inf, exit 0
    (["montecarlo", "--d-total", "0.5"], "--d1"),  # said `geometry`
    (["montecarlo", "--alpha", "1e300"], "--alpha"),
    (["plan", DEFAULT, "--eps", "0.01"], "--eps"),  # asked numpy for 182 GiB
])
def test_every_refusal_is_one_line_naming_the_flag(capsys, argv, says):
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's own refusals exit from inside the parser
        status = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and says in err[0], err


def test_keep_given_twice_keeps_both():
    """`--keep ids --keep annotated` kept only the last, silently."""
    from mirrorsim.cli.main import build_parser

    for cmd in ("evaluate", "budget", "dataset"):
        argv = [cmd, DEFAULT, "--keep", "ids", "--keep", "annotated"]
        if cmd == "dataset":
            argv = [cmd, "--n", "1", "--seed", "0", "--out", "d", "--keep", "ids", "--keep",
                    "annotated"]
        assert build_parser(argv).parse_args(argv).keep == ["ids", "annotated"]


def test_progress_is_a_bar_on_a_terminal_and_plain_lines_in_a_log(monkeypatch):
    """A bar's carriage returns filled logs with one line of every redraw: off a terminal
    progress is a plain line at most every LINE_SECONDS and one at the end; a transient
    bar (a render's, under a run's own) says nothing there."""
    import io as _io

    from mirrorsim import progress as pr

    class Tty(_io.StringIO):
        def isatty(self):
            return True

    from tqdm import tqdm

    assert isinstance(pr.progress_bar(3, stream=Tty()), tqdm)
    log = _io.StringIO()
    clock = iter([0.0, 5.0, 12.0, 13.0, 30.0])
    monkeypatch.setattr(pr.time, "monotonic", lambda: next(clock, 30.0))
    with pr.progress_bar(4, desc="dataset", unit="scene", stream=log) as bar:  # t = 0
        bar.update()  # t = 5: too soon for a line
        bar.update()  # t = 12: a line, with its rate and ETA
        bar.update()  # t = 13
    lines = log.getvalue().splitlines()  # and the last line, at t = 30
    assert "\r" not in log.getvalue() and len(lines) == 2
    assert lines[0] == "dataset: 2/4 scene, 12 s, 0.167 scene/s, ETA 12 s"
    assert lines[1].startswith("dataset: 3/4 scene, 30 s")
    quiet = _io.StringIO()
    with pr.progress_bar(4, stream=quiet, leave=False) as bar:
        bar.update(4)
    with pr.progress_bar(4, stream=quiet, enabled=False) as bar:
        bar.update(4)
    assert quiet.getvalue() == ""
