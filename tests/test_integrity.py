"""Integrity (README "Reliability"): what is read from disk is verified before it is
trusted, and concurrent runs do not lose each other's work."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mirrorsim.formats.cache import entry_path, read_entry, write_entry
from mirrorsim.pipelines import calibrate as cal_mod
from mirrorsim.scene.model import Camera

# ------------------------------------------------------------------- cached entries


@pytest.fixture
def fake_reference(monkeypatch, tmp_path):
    """Calibration with a stand-in for the reference render: 230 px for the target,
    47 px for the pencil, counting the measurements made."""
    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path))
    calls = []

    def measure(_camera, kind, *_rest, **_kw):
        calls.append(kind)
        return 230.0 if kind == "target" else 47.0

    monkeypatch.setattr(cal_mod, "measure_reference", measure)
    return calls


CAMERA = Camera(position=(0.0, 0.0), height=10.0, resolution=(1920, 1088), hfov=60.0,
                pan=45.0, pan_deg=45.0)


def _entry_file() -> tuple[str, object]:
    key = cal_mod.calibration_key(CAMERA, (10.0, 10.0), 17.5)
    return key, entry_path("calibration", key)


def test_a_calibration_is_reused_only_while_it_verifies(fake_reference):
    first = cal_mod.calibrate(CAMERA, (10.0, 10.0), 17.5)
    assert fake_reference == ["target", "beacon"]
    assert cal_mod.calibrate(CAMERA, (10.0, 10.0), 17.5) == first  # reused
    assert len(fake_reference) == 2
    key, path = _entry_file()
    entry = json.loads(path.read_text())

    # K scaled by 1.10 with the checksum made to match: K no longer follows from the
    # measured height (eq 5); without the checksum mended, the checksum catches it
    cases = []
    scaled = json.loads(json.dumps(entry))
    scaled["value"]["target_k"] *= 1.10
    cases.append((scaled, "checksum"))
    mended = json.loads(json.dumps(scaled))
    from mirrorsim.formats.cache import checksum
    mended["sha256"] = checksum({"key": key, "value": mended["value"]})
    cases.append((mended, "does not follow"))
    missing = json.loads(json.dumps(entry))
    del missing["value"]["pencil_k"]
    missing["sha256"] = checksum({"key": key, "value": missing["value"]})
    cases.append((missing, "pencil_k"))
    wrong_type = json.loads(json.dumps(entry))
    wrong_type["value"]["target_k"] = "2.3e4"
    wrong_type["sha256"] = checksum({"key": key, "value": wrong_type["value"]})
    cases.append((wrong_type, "must be numbers"))
    other_key = json.loads(json.dumps(entry))
    other_key["key"] = key.replace("hfov=60", "hfov=61")
    cases.append((other_key, "another key"))
    for damaged, why in cases:
        path.write_text(json.dumps(damaged))
        n = len(fake_reference)
        with pytest.warns(RuntimeWarning, match=why):
            again = cal_mod.calibrate(CAMERA, (10.0, 10.0), 17.5)
        assert again == first and len(fake_reference) == n + 2  # measured again
        assert read_entry("calibration", key) is not None  # and the entry mended
    path.write_text(path.read_text()[:40])  # truncated
    with pytest.warns(RuntimeWarning, match="not trusted"):
        assert cal_mod.calibrate(CAMERA, (10.0, 10.0), 17.5) == first


_WRITER = """
import sys
from mirrorsim.formats.cache import write_entry
who = sys.argv[1]
for i in range(40):
    write_entry("calibration", f"{who}-{i}", {"who": who, "i": i})
"""


def test_concurrent_writers_keep_every_entry(tmp_path, monkeypatch):
    """Four real processes writing 40 entries each into one empty cache, at once: all
    160 are there and verify."""
    env = {"MIRRORSIM_CACHE_DIR": str(tmp_path), "PATH": "/usr/bin:/bin"}
    procs = [subprocess.Popen([sys.executable, "-c", _WRITER, who], env=env)
             for who in "abcd"]
    assert all(p.wait(timeout=120) == 0 for p in procs)
    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path))
    found = [read_entry("calibration", f"{who}-{i}") for who in "abcd" for i in range(40)]
    assert found == [{"who": who, "i": i} for who in "abcd" for i in range(40)]
    assert not [p for p in (tmp_path / "calibration").iterdir() if p.name.startswith(".")]


def test_a_cache_entry_for_another_key_is_not_taken(tmp_path, monkeypatch):
    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path))
    write_entry("calibration", "a", {"v": 1})
    entry_path("calibration", "a").replace(entry_path("calibration", "b"))
    with pytest.warns(RuntimeWarning, match="another key"):
        assert read_entry("calibration", "b") is None


# ------------------------------------------------------------------- cached frames


def test_a_cached_frame_is_reused_only_while_its_bytes_verify(tmp_path):
    """Truncated, swapped for another scene's render, or its truth edited: rendered
    again with a warning (and the same bytes come back: renders are deterministic)."""
    import warnings

    from mirrorsim.pipelines.frame import render_to_files

    from .conftest import small_scene

    scene = small_scene("default", 160, 92, spp=2, beacon_spp=4, background_spp=1)
    other = small_scene("exp2", 160, 92, spp=2, beacon_spp=4, background_spp=1)
    first = render_to_files(scene, tmp_path / "a", progress=False)
    good = first.image.read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an intact frame is reused without a word
        assert render_to_files(scene, tmp_path / "a", progress=False, reuse=True).reused
    swapped = render_to_files(other, tmp_path / "b", progress=False).image.read_bytes()

    def edit_truth(path):
        path.write_text(path.read_text().replace('"d_total": ', '"d_total": 1', 1))

    for damage, why in ((lambda: first.image.write_bytes(good[: len(good) // 2]), "bytes"),
                        (lambda: first.image.write_bytes(swapped), "bytes"),
                        (lambda: edit_truth(first.truth_json), "checksum"),
                        (lambda: first.capture_json.write_text("{}"), "bytes")):
        damage()
        with pytest.warns(RuntimeWarning, match=why):
            again = render_to_files(scene, tmp_path / "a", progress=False, reuse=True)
        assert not again.reused and again.image.read_bytes() == good


# ------------------------------------------ every value that passes `check` renders


@pytest.mark.parametrize("edit, key", [
    (lambda d: d["mirror"].update(curvature_radius=1e308), "mirror.curvature_radius"),
    (lambda d: d["mirror"].update(curvature_radius=-2e7), "mirror.curvature_radius"),
    (lambda d: d["camera"].update(noise={"full_well": 1e300, "read_noise": 2}),
     "camera.noise.full_well"),
    (lambda d: d["camera"].update(noise={"full_well": 1e4, "read_noise": 1e9}),
     "camera.noise.read_noise"),
    (lambda d: d["camera"].update(resolution=[100000, 100000]), r"camera.resolution\[0\]"),
    (lambda d: d["camera"].update(resolution=[1920, 5000]), r"camera.resolution\[1\]"),
    (lambda d: d["board"].update(size=[1e5, 1e5]), r"board.size\[0\]"),
    (lambda d: d["board"].update(size=[80, 201]), r"board.size\[1\]"),
])
def test_check_refuses_values_beyond_the_documented_bounds(tmp_path, capsys, edit, key):
    import yaml

    from mirrorsim.cli.main import main

    from .conftest import scene_dict

    d = scene_dict("default")
    edit(d)
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and re.search(f"s.yaml: {key}: ", err), err


def test_a_scene_at_the_bounds_renders():
    """The largest board, the flattest curved mirror and the largest sensor noise that
    `check` accepts: rendered, and every pixel finite."""
    import copy

    import numpy as np

    from mirrorsim.pipelines.scenes import scene_from_dict
    from mirrorsim.rendering.passes import render_frame
    from mirrorsim.scene.model import MAX_BOARD_CM, MAX_CURVATURE_RADIUS, MAX_FULL_WELL

    from .conftest import scene_dict

    d = copy.deepcopy(scene_dict("default"))
    d["board"]["size"] = [MAX_BOARD_CM, MAX_BOARD_CM]
    d["mirror"]["curvature_radius"] = -MAX_CURVATURE_RADIUS
    d["camera"].update(resolution=[160, 92], noise={"full_well": MAX_FULL_WELL,
                                                     "read_noise": 100.0})
    d["render"] = {"spp": 1, "beacon_spp": 1, "background_spp": 1}
    frame = render_frame(scene_from_dict(d, "bounds.yaml"), progress=False)
    assert frame.linear.shape == (92, 160, 3) and np.isfinite(frame.linear).all()


@pytest.mark.parametrize("argv, says", [
    (["--odometry-sigma", "1e300"], "--odometry-sigma: 1e+300 must be within 0..10"),
    (["--side", "200"], "--side: 200 must be a positive length (cm) within the board's 80"),
    (["--step", "81"], "--step: 81 must be"),
    (["--spp", "70000"], "--spp: 70000 must be a whole number within 1..65536"),
])
def test_track_refuses_paths_off_the_board_and_absurd_noise(tmp_path, capsys, argv, says):
    from mirrorsim.cli.main import main

    from .conftest import SCENES

    assert main(["track", str(SCENES / "default.yaml"), "--out", str(tmp_path / "t"),
                 "--quiet", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err
    assert not (tmp_path / "t").exists()


# ------------------------------------------ outputs land only where they may


def _refused(capsys, argv, says):
    from mirrorsim.cli.main import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err


def test_a_folder_of_the_users_files_is_not_written_into(tmp_path, capsys):
    """A user's file named like the frame stays as it was; nothing else appears."""
    from .conftest import SCENES

    user = tmp_path / "photos"
    user.mkdir()
    (user / "default.png").write_bytes(b"my holiday")
    for cmd in ("render", "evaluate", "budget", "track"):
        _refused(capsys, [cmd, str(SCENES / "default.yaml"), "--out", str(user), "--quiet"],
                 "holds files mirrorsim did not write ('default.png')")
    assert [p.name for p in user.iterdir()] == ["default.png"]
    assert (user / "default.png").read_bytes() == b"my holiday"


def test_no_output_over_another_output_of_the_run(tmp_path, capsys):
    from .conftest import SCENES

    scene = str(SCENES / "default.yaml")
    _refused(capsys, ["check", scene, "--json", str(tmp_path / "a.json"),
                      "--measurements", str(tmp_path / "a.json")], "--json writes this file too")
    out = tmp_path / "out"
    out.mkdir()
    # the run names the files of its folder: a --json there could be its frame
    _refused(capsys, ["evaluate", scene, "--out", str(out), "--json", str(out / "default.png")],
             "inside the run's output folder")
    assert list(tmp_path.iterdir()) == [out] and not list(out.iterdir())


@pytest.mark.parametrize("link", ["dangling", "looping"])
def test_a_broken_link_as_out_is_refused(tmp_path, capsys, link):
    from .conftest import SCENES

    out = tmp_path / "out"
    out.symlink_to(tmp_path / "nowhere" if link == "dangling" else out)
    _refused(capsys, ["render", str(SCENES / "default.yaml"), "--out", str(out)],
             "a symbolic link to nothing")
    _refused(capsys, ["check", str(SCENES / "default.yaml"), "--json", str(out)],
             "a symbolic link to nothing")


@pytest.mark.parametrize("cmd, out", [("plot", "topview"), ("plan", "plan.txt"),
                                      ("plot", "top.jpeg")])
def test_a_plot_without_a_format_suffix_is_refused(tmp_path, capsys, cmd, out):
    from .conftest import SCENES

    _refused(capsys, [cmd, str(SCENES / "default.yaml"), "--out", str(tmp_path / out)],
             "the format goes by the file's suffix: use .png, .pdf, .svg")
    assert not list(tmp_path.iterdir())


def test_odd_scene_file_names_get_one_line(tmp_path, capsys):
    """A newline in the file name is shown escaped; a file name that cannot be the
    scene's name is blamed on the missing `name:`, not on a key the file lacks."""
    import yaml

    from .conftest import scene_dict

    bad = tmp_path / "two\nlines.yaml"
    bad.write_text("board: 3\n")
    _refused(capsys, ["check", str(bad)], "two\\nlines.yaml': camera: missing required key")
    d = scene_dict("default")
    del d["name"]
    spaced = tmp_path / "my scene.yaml"
    spaced.write_text(yaml.safe_dump(d))
    _refused(capsys, ["check", str(spaced)], "my scene.yaml: has no `name:` and its file "
             "name 'my scene' cannot stand in for one")


# ------------------------------------------------------------------------ signals


def _cli(*argv: str, env: dict | None = None) -> subprocess.Popen:
    """The command as a terminal's foreground job runs it (SIGINT not ignored), in a
    session of its own so that its workers can be found."""
    import os
    import signal

    return subprocess.Popen([sys.executable, "-m", "mirrorsim", *argv], text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, env={**os.environ, **(env or {})},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


@pytest.mark.parametrize("delay", [0.02, 0.1, 0.2])
def test_ctrl_c_while_the_command_starts_is_a_clean_interrupt(delay):
    """While the commands' modules import (NumPy, SciPy): exit 130, one line.  The delay
    counts from when the entry point runs (the interpreter's own start-up, measured
    here, keeps Python's Ctrl-C)."""
    import signal
    import time

    from .conftest import SCENES

    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import mirrorsim.cli.entry"], check=True)
    start_up = time.perf_counter() - t0
    proc = _cli("check", str(SCENES / "default.yaml"))
    time.sleep(start_up + delay)
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=60)
    # finished first: exit 0, or killed by the signal after the interpreter's own
    # clean-up restored its default action (nothing of mirrorsim runs then)
    if proc.returncode == 0 or (proc.returncode == -2 and not err):
        pytest.skip("the command finished before the signal")
    assert proc.returncode == 130 and err == "interrupted\n", err


def test_ctrl_c_during_a_calibration_render_exits_130(tmp_path):
    """Dr.Jit turns an interrupt inside a render into a RuntimeError: still 130, one
    line, and no calibration cached."""
    import shutil
    import signal
    import time

    from mirrorsim.formats.cache import cache_root
    from mirrorsim.rendering import backend

    # the backend's answer known (the session's), so that the renders start at once
    if not backend.probe("llvm_ad_rgb")[0]:
        pytest.skip("no LLVM backend here: the interrupt to wrap is Dr.Jit's")
    shutil.copytree(cache_root() / "backend", tmp_path / "backend")
    import yaml

    from .conftest import scene_dict

    d = scene_dict("default")
    # the largest film a scene takes: ~8 s of calibration renders on a 2-core machine
    # (at 4× the pixels, ~3 s: the interrupt raced the process's exit)
    d["camera"]["resolution"] = [7680, 4320]
    big = tmp_path / "big.yaml"
    big.write_text(yaml.safe_dump(d))
    proc = _cli("calibrate", str(big), "--variant", "llvm",
                env={"MIRRORSIM_CACHE_DIR": str(tmp_path)})
    time.sleep(3.0)  # imports (~1 s), then the reference renders
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("the calibration finished before the signal (a fast machine)")
    assert proc.returncode == 130 and err == "interrupted\n", err
    assert not (tmp_path / "calibration").exists()


def _session_gone(pgid: int, seconds: float) -> bool:
    import os
    import time

    t0 = time.time()
    while time.time() - t0 < seconds:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("sig", ["SIGKILL", "SIGTERM"])
def test_a_dataset_parent_killed_alone_takes_its_workers_with_it(tmp_path, sig):
    """The signal to the parent only (not its process group): no worker lives on to
    finish its scene; SIGTERM exits 143 like an interrupt; the rows on disk verify and
    --resume finishes the dataset."""
    import os
    import signal
    import time

    from mirrorsim.pipelines.dataset import collect_rows

    spec = Path(__file__).parent / "data" / "tiny_spec.yaml"
    out = tmp_path / "ds"
    argv = ("dataset", "--n", "4", "--seed", "5", "--out", str(out), "--spec", str(spec),
            "--workers", "2", "--quiet")
    proc = _cli(*argv)
    deadline = time.time() + 120
    while time.time() < deadline and not list((out / "rows").glob("scene*.json")):
        time.sleep(0.05)
    proc.send_signal(getattr(signal, sig))
    _out, err = proc.communicate(timeout=60)
    if sig == "SIGTERM":
        assert proc.returncode == 143 and "terminated" in err, err
    else:
        assert proc.returncode == -9
    assert _session_gone(proc.pid, 10), "a worker outlived its parent"
    rows = collect_rows(out, 4)  # each row on disk verifies
    assert 1 <= len(rows) < 4
    finish = subprocess.run([sys.executable, "-m", "mirrorsim", *argv, "--resume"],
                            capture_output=True, text=True, env=os.environ)
    assert finish.returncode == 0, finish.stderr
    assert len(collect_rows(out, 4)) == 4


def test_a_killed_writers_temporary_file_is_swept(tmp_path):
    """kill -9 between writing and renaming leaves `.NAME.mirrorsim-tmpPID.png`: the next
    write into that folder removes it when PID is gone (a live writer's is left alone,
    and a user's file named like an editor's temporary file too: one was swept away)."""
    import os

    from mirrorsim.formats.files import write_text

    dead = tmp_path / ".frame.mirrorsim-tmp999999999.png"  # no such process
    dead_json = tmp_path / ".frame.capture.mirrorsim-tmp999999998.json"
    live = tmp_path / f".frame.mirrorsim-tmp{os.getppid()}.png"
    users = [tmp_path / n for n in (".notes.txt", ".plan.tmp999999997.yaml",
                                    ".draft.tmp1999.txt")]
    for p in (dead, dead_json, live, *users):
        p.write_bytes(b"half a frame")
    write_text(tmp_path / "report.json", "x")
    assert not dead.exists() and not dead_json.exists()
    assert live.exists() and all(p.exists() for p in users)


# ------------------------------------------------------ resource bombs and odd files


def _deep_json(depth: int) -> str:
    return "[" * depth + "]" * depth


@pytest.mark.parametrize("cmd", ["solve", "detect", "plan"])
def test_json_nested_absurdly_deep_is_one_line(tmp_path, capsys, cmd):
    """As measurements, a capture record and an error model."""
    from .conftest import SCENES

    bomb = tmp_path / "bomb.json"
    bomb.write_text(_deep_json(100_000))
    frame = tmp_path / "f.png"
    frame.write_bytes(b"\x89PNG\r\n\x1a\n")
    argv = {"solve": ["solve", str(bomb)],
            "detect": ["detect", str(frame), "--capture", str(bomb)],
            "plan": ["plan", str(SCENES / "default.yaml"), "--error-model", str(bomb)]}[cmd]
    _refused(capsys, argv, "bomb.json: malformed JSON: nested too deeply")


@pytest.mark.parametrize("cmd", ["check", "dataset"])
def test_yaml_nested_absurdly_deep_is_one_line(tmp_path, capsys, cmd):
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    argv = ([cmd, str(bomb)] if cmd == "check" else
            ["dataset", "--n", "1", "--seed", "1", "--out", str(tmp_path / "d"), "--spec",
             str(bomb)])
    _refused(capsys, argv, "bomb.yaml: malformed YAML: nested too deeply")
    assert not (tmp_path / "d").exists()


def test_numbers_past_pythons_digit_limit_are_one_line(tmp_path, capsys):
    f = tmp_path / "m.json"
    f.write_text('{"alpha": ' + "9" * 5000 + "}")
    _refused(capsys, ["solve", str(f)], "m.json: malformed JSON: ")


@pytest.mark.parametrize("kind", ["png", "jpeg"])
def test_a_huge_frame_is_refused_from_its_header(tmp_path, capsys, kind):
    """A 30000×30000 image (1 MB of zeros compresses well) is refused before decoding:
    reading its header is enough, and the refusal names both sizes."""
    import struct
    import time
    import zlib

    frame = tmp_path / f"huge.{'png' if kind == 'png' else 'jpg'}"
    if kind == "png":
        def chunk(tag, data):
            return (struct.pack(">I", len(data)) + tag + data
                    + struct.pack(">I", zlib.crc32(tag + data)))
        frame.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(
            ">IIBBBBB", 30000, 30000, 8, 0, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(
                b"\0" * 30001 * 300)) + chunk(b"IEND", b""))
    else:  # SOI, then a baseline start-of-frame claiming 60000×60000
        frame.write_bytes(b"\xff\xd8" + b"\xff\xc0\x00\x11\x08" + struct.pack(">HH", 60000, 60000)
                          + b"\x03\x01\x22\x00\x02\x11\x01\x03\x11\x01" + b"\xff\xd9")
    size = "30000×30000" if kind == "png" else "60000×60000"
    t0 = time.perf_counter()
    _refused(capsys, ["detect", str(frame), "--capture", str(_capture(tmp_path))],
             f"the frame is {size} px but the capture record's camera is 1920×1088")
    assert time.perf_counter() - t0 < 30  # no decode (which took 20 s and 5 GB)


def _capture(tmp_path) -> Path:
    from mirrorsim.formats.capture import CaptureRecord
    from mirrorsim.formats.files import write_json
    from mirrorsim.pipelines.scenes import load_scene

    from .conftest import SCENES

    scene = load_scene(SCENES / "default.yaml")
    return write_json(tmp_path / "cap.json", CaptureRecord.from_scene(scene, "f.png").to_json())


def test_a_fifo_as_a_scene_is_refused_not_waited_on(tmp_path, capsys):
    import os

    fifo = tmp_path / "scene.yaml"
    os.mkfifo(fifo)
    _refused(capsys, ["check", str(fifo)], "not a regular file")


def test_an_output_name_too_long_is_one_line(tmp_path, capsys):
    from .conftest import SCENES

    _refused(capsys, ["render", str(SCENES / "default.yaml"), "--out",
                      str(tmp_path / ("x" * 300))], "File name too long")


@pytest.mark.parametrize("cores, free_mb, asked, runs", [
    (64, 3.5 * 1024, 64, 3),  # memory decides: 3 workers of 1 GiB
    (2, 64 * 1024, 64, 2),  # the cores decide
    (2, 64 * 1024, 2, 2),  # within both: untouched, no warning
])
def test_dataset_workers_are_capped_by_cores_and_memory(monkeypatch, capsys, tmp_path,
                                                        cores, free_mb, asked, runs):
    import os

    from mirrorsim.cli.main import main
    from mirrorsim.errors import RunFailed
    from mirrorsim.pipelines import dataset, workers

    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: set(range(cores)))
    monkeypatch.setattr(workers, "available_mb", lambda: free_mb)
    given = []

    def run_dataset(*_args, **kwargs):
        given.append(kwargs["workers"])
        raise RunFailed("stopped here by the test")

    monkeypatch.setattr(dataset, "run_dataset", run_dataset)
    assert main(["dataset", "--n", "4", "--seed", "1", "--out", str(tmp_path / "d"),
                 "--workers", str(asked), "--quiet"]) == 1
    assert given == [runs]
    err = capsys.readouterr().err
    if asked > runs:
        assert err.startswith(f"warning: --workers {asked} capped to {runs} ({cores} cores")
    else:
        assert "warning" not in err


_READ_ONLY = 'mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" && cd "$0" && exec "$@"'


@pytest.mark.parametrize("cmd", ["render", "evaluate", "plot", "budget", "track", "plan"])
def test_the_default_folder_in_a_read_only_directory_is_one_line(tmp_path, cmd):
    """renders/ cannot be made where the command runs: exit 2 naming --out, nothing
    written.  (Root ignores permission bits: the folder is a read-only bind mount.)"""
    import shutil

    from .conftest import SCENES

    ro = tmp_path / "ro"
    ro.mkdir()
    probe = subprocess.run(["unshare", "-m", "sh", "-c", _READ_ONLY, str(ro), "sh", "-c",
                            "touch x 2>/dev/null && echo writable || echo read-only"],
                           capture_output=True, text=True) if shutil.which("unshare") else None
    if probe is None or probe.stdout.strip() != "read-only":
        pytest.skip("no read-only bind mount here (unshare -m needs root)")
    proc = subprocess.run(["unshare", "-m", "sh", "-c", _READ_ONLY, str(ro), sys.executable,
                           "-m", "mirrorsim", cmd, str(SCENES / "default.yaml")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "--out" in proc.stderr and "renders" in \
        proc.stderr, proc.stderr
    assert not list(ro.iterdir())


def test_frame_sizes_read_from_headers_match_the_decoded_images():
    """PNG, baseline JPEG, a JPEG with a 60 KB APP1 segment and fill bytes before its
    next marker, and damaged headers."""
    import cv2
    import numpy as np

    from mirrorsim.detection.frame_files import header_size

    img = np.zeros((37, 53, 3), np.uint8)
    png = cv2.imencode(".png", img)[1].tobytes()
    jpg = cv2.imencode(".jpg", img)[1].tobytes()
    payload = b"Exif\0\0" + b"x" * 60_000
    app1 = b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload
    padded = jpg[:2] + app1 + b"\xff\xff\xff" + jpg[2:]
    assert cv2.imdecode(np.frombuffer(padded, np.uint8), cv2.IMREAD_COLOR).shape == (37, 53, 3)
    for data in (png, jpg, padded):
        assert header_size(data) == (53, 37)
    assert header_size(png[:20]) is None and header_size(b"\xff\xd8\x00\x00" * 4) is None


def test_errormodel_plots_never_go_over_a_file_that_is_not_a_models(tmp_path, capsys):
    """--out notes/model.json puts its plots in notes/model.png: a user's model.png
    there (without a model.json beside it) is refused before any work."""
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "model.png").write_bytes(b"my figure")
    _refused(capsys, ["errormodel", str(tmp_path / "ds"), "--out", str(notes / "model.json")],
             "its plots would go over")
    assert (notes / "model.png").read_bytes() == b"my figure"
    assert [p.name for p in notes.iterdir()] == ["model.png"]


def test_a_cached_frame_without_its_ids_is_rendered_again_when_they_are_asked(tmp_path):
    from mirrorsim.pipelines.frame import render_to_files

    from .conftest import small_scene

    scene = small_scene("default", 160, 92, spp=2, beacon_spp=4, background_spp=1)
    first = render_to_files(scene, tmp_path, progress=False, ids=False)
    assert first.ids_png is None and not (tmp_path / "default.ids.png").exists()
    again = render_to_files(scene, tmp_path, progress=False, reuse=True, ids=True)
    assert not again.reused and again.ids_png.exists()
    assert render_to_files(scene, tmp_path, progress=False, reuse=True, ids=True).reused


def test_a_calibrations_key_covers_all_the_code_it_comes_out_of():
    """The calibration cache's key holds a hash of the code a K comes out of.  That code
    is read off the imports (a list kept by hand had missed detection/regions.py, where
    the segmentation moved); held here against what a process actually loads to
    calibrate, and without importing Mitsuba to make the key."""
    import subprocess
    import sys

    from mirrorsim.pipelines.calibrate import code_modules

    covered = code_modules()
    assert {"mirrorsim.detection.regions", "mirrorsim.detection.edges",
            "mirrorsim.scene.model", "mirrorsim.camera.sensor",
            "mirrorsim.rendering.passes"} <= set(covered)
    assert all(p.is_file() for p in covered.values())
    assert all(n.split(".")[0] in ("mirrorsim", "solver") for n in covered)
    probe = ("import sys, mirrorsim.pipelines.calibrate as c; c.code_fingerprint(); "
             "print('mitsuba' in sys.modules); "
             "import mirrorsim.rendering.passes; "  # what a calibration's render imports
             "print(' '.join(n for n, m in sys.modules.items() if n.split('.')[0] in "
             "('mirrorsim', 'solver') and not hasattr(m, '__path__')))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[0] == "False"  # the key is made without Mitsuba
    assert set(out[1].split()) <= set(covered), set(out[1].split()) - set(covered)


def test_the_code_fingerprint_cached_is_the_one_computed(tmp_path, monkeypatch):
    """The fingerprint cached by the digest of every source file is the one its modules'
    sources give; a damaged entry is distrusted (one warning) and made again."""
    import hashlib
    import json

    from mirrorsim.pipelines import calibrate

    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path / "cache"))
    h = hashlib.sha256()
    for name, path in calibrate.code_modules().items():
        h.update(name.encode() + b"\0" + path.read_bytes())
    calibrate.code_fingerprint.cache_clear()
    assert calibrate.code_fingerprint() == h.hexdigest()[:12]  # computed, then cached
    entries = list((tmp_path / "cache" / "code").glob("*.json"))
    assert len(entries) == 1
    entry = entries[0]
    calibrate.code_fingerprint.cache_clear()
    assert calibrate.code_fingerprint() == h.hexdigest()[:12]  # read back
    doc = json.loads(entry.read_text())
    doc["value"]["fingerprint"] = "0" * 12  # another code's, checksum now wrong
    entry.write_text(json.dumps(doc))
    calibrate.code_fingerprint.cache_clear()
    with pytest.warns(RuntimeWarning, match="not trusted"):
        assert calibrate.code_fingerprint() == h.hexdigest()[:12]
    calibrate.code_fingerprint.cache_clear()


def test_a_fifo_where_a_file_is_read_back_is_distrusted_not_waited_on(tmp_path,
                                                                       monkeypatch):
    """A FIFO in place of a cache entry, a frame's file or a row made the read wait for
    a writer for ever; now it is a file that fails verification (redone, or rejected)."""
    import os

    from mirrorsim.formats import cache
    from mirrorsim.formats.files import read_regular_bytes

    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path / "cache"))
    cache.write_entry("calibration", "k", {"K": 1.0})
    path = cache.entry_path("calibration", "k")
    path.unlink()
    os.mkfifo(path)
    with pytest.warns(RuntimeWarning, match="not a regular file"):
        assert cache.read_entry("calibration", "k") is None
    with pytest.raises(OSError, match="not a regular file"):
        read_regular_bytes(path)
    (tmp_path / "f.json").write_bytes(b"{}")
    assert read_regular_bytes(tmp_path / "f.json") == b"{}"


# ------------------------------------------------------------------- error model files


def test_an_error_model_is_used_only_while_its_checksum_holds(tmp_path):
    """A model mirrorsim wrote carries its checksum: a σ's digit changed within every
    range (which passes each other check) is refused, naming the key; a model written by
    hand (no checksum) is read as before; the shipped model is sealed."""
    from mirrorsim.formats.error_model import ErrorModelError, default_model_path
    from mirrorsim.formats.error_model_file import default_error_model, load_error_model
    from mirrorsim.pipelines.errormodel import write_model

    assert "sha256" in json.loads(default_model_path().read_text())
    path = tmp_path / "model.json"
    write_model(default_error_model(), path)
    data = json.loads(path.read_text())
    assert load_error_model(path) == default_error_model()
    law = data["objects"]["beacon"]["d_rel"]["log_sigma"]
    law["intercept"] = round(law["intercept"] - 0.5, 6)  # σ × 0.6: still a plausible σ
    path.write_text(json.dumps(data))
    with pytest.raises(ErrorModelError, match=r"sha256.*damaged or edited") as exc:
        load_error_model(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)
    del data["sha256"]  # a model edited on purpose, by hand
    path.write_text(json.dumps(data))
    edited = load_error_model(path)
    assert edited.fits["beacon"]["d_rel"].log_sigma.intercept == law["intercept"]
    assert edited.source == str(path) and edited != default_error_model()


def test_a_datasets_card_names_the_error_model_file_it_was_made_with(tmp_path, monkeypatch):
    """The card's command named a model other than the shipped one only as MODEL (with
    its hash): it now names the file given, and the hash it had then."""
    from dataclasses import replace

    from mirrorsim.formats.dataset_card import made_with
    from mirrorsim.formats.error_model_file import default_error_model, load_error_model
    from mirrorsim.pipelines import dataset as ds
    from mirrorsim.pipelines.errormodel import write_model

    model_path = tmp_path / "bench_model.json"
    write_model(replace(default_error_model(), shared_alpha_deg=0.05), model_path)

    class Stop(Exception):
        pass

    def stop(*_a, **_k):  # the folder is claimed and described: stop before rendering
        raise Stop

    monkeypatch.setattr(ds, "_calibrate_models", stop)
    out = tmp_path / "ds"
    with pytest.raises(Stop):
        ds.run_dataset(1, 5, out, workers=1, progress=False,
                       error_model=load_error_model(model_path))
    meta = json.loads((out / "dataset.json").read_text())
    assert meta["error_model_file"] == str(model_path)
    assert f"--error-model {model_path}" in made_with(meta, out)
    shipped = tmp_path / "shipped"
    with pytest.raises(Stop):  # the shipped model: no file, no option
        ds.run_dataset(1, 5, shipped, workers=1, progress=False)
    meta = json.loads((shipped / "dataset.json").read_text())
    assert "error_model_file" not in meta and "--error-model" not in made_with(meta, shipped)
    # a model read from a file and changed in memory still names that file: not its file
    edited = tmp_path / "edited"
    with pytest.raises(Stop):
        ds.run_dataset(1, 5, edited, workers=1, progress=False,
                       error_model=replace(load_error_model(model_path), shared_alpha_deg=0.1))
    meta = json.loads((edited / "dataset.json").read_text())
    assert meta["error_model_shipped"] is False and "error_model_file" not in meta
    assert "--error-model MODEL" in made_with(meta, edited)


@pytest.mark.usefixtures("fake_reference")  # calibrate measures no render here
def test_pencils_of_two_heights_in_one_frame_are_refused_not_scaled_alike(tmp_path, capsys):
    """One calibration measures one pencil's K: a frame of a 4.2 cm and a 6 cm pencil
    scaled both by the first's (the 6 cm one, 4.8 cm of paint against 3.0, would read
    37.5 % near).  Detecting such a frame is
    refused before the frame is read; `calibrate` says whose K it printed."""
    import yaml

    import mirrorsim as ms
    from mirrorsim.cli.main import main
    from mirrorsim.formats.capture import CaptureError, CaptureRecord
    from mirrorsim.formats.files import write_json
    from mirrorsim.pipelines.frame import measure_frame

    from .conftest import SCENES

    base = ms.load_scene(SCENES / "default.yaml")
    two = ms.edit_scene(base, {"beacons": [
        {"position": list(base.beacons[0].position), "height": 4.2},
        {"position": [36, 53], "height": 6.0}]})
    capture = CaptureRecord.from_scene(two, "two.png")
    with pytest.raises(CaptureError, match=r"pencils of 4\.2, 6 cm in one frame"):
        measure_frame(tmp_path / "two.png", capture)  # no such file: refused before
    record = write_json(tmp_path / "two.capture.json", capture.to_json())
    (tmp_path / "two.png").write_bytes(b"")
    assert main(["detect", str(tmp_path / "two.png"), "--capture", str(record)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "in one frame" in err[0]
    doc = yaml.safe_load((SCENES / "default.yaml").read_text())
    doc["beacons"] = [{**doc.pop("beacon"), "height": 4.2},
                      {"position": [36, 53], "height": 6.0}]
    (tmp_path / "two.yaml").write_text(yaml.safe_dump(doc))
    assert main(["calibrate", str(tmp_path / "two.yaml")]) == 0
    assert "the 6 cm pencils get theirs" in capsys.readouterr().err
