"""The Python API: `import mirrorsim` and its entry points."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import mirrorsim as ms

ROOT = Path(__file__).resolve().parents[1]


def test_import_is_cheap_and_every_entry_point_resolves():
    code = ("import sys, json, mirrorsim; print(json.dumps([m for m in ('mitsuba', 'scipy', "
            "'pandas', 'matplotlib', 'cv2') if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert json.loads(out.stdout) == []
    for name in ms.__all__:
        assert name == "__version__" or callable(getattr(ms, name)), name
    with pytest.raises(AttributeError):
        ms.no_such_thing  # noqa: B018


def test_the_api_returns_the_typed_values_the_cli_prints():
    scene = ms.load_scene(ROOT / "scenes" / "exp1.yaml")
    truth = ms.check(scene)
    assert truth.target.alpha_deg == pytest.approx(66.678, abs=1e-3)  # the scene's comment
    m = truth.exact_measurements()
    sol = ms.solve(m.observer, m.beacons, m.targets)
    assert sol.target == pytest.approx(scene.target.position, abs=1e-6)
    # exact measurements of a flat mirror: self-calibration finds no pan and no scale
    three = ms.load_scene(ROOT / "scenes" / "bench" / "exp1_3beacons.yaml")
    many = ms.check(three).exact_measurements()  # at the beacons' true positions
    assert len(many.beacons) == 3
    cal = ms.solve(many.observer, many.beacons, many.targets, sigma=None,
                   calibration=ms.SelfCalibration(("pan", "scale")))
    assert cal.nuisances["pan_offset_deg"] == pytest.approx(0.0, abs=1e-6)
    assert cal.nuisances["range_scale"] == pytest.approx(1.0, abs=1e-8)
    assert cal.target == pytest.approx(three.target.position, abs=1e-6)
    assert ms.load_error_model(None).typical.target.alpha_deg > 0


@pytest.mark.slow
def test_the_example_sweeps_a_yaw_and_plots(tmp_path):
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "sweep_yaw.py"), "--yaws",
                          "18", "22", "--width", "960", "--out", str(tmp_path)],
                         capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.count("target error") == 2
    assert (tmp_path / "sweep_yaw.png").read_bytes()[:4] == b"\x89PNG"


def test_the_api_keeps_the_command_lines_promises(tmp_path):
    """A script calling the library gets what the command line refuses refused too,
    before anything is rendered or written (a hostile sweep of the API found each)."""
    import shutil

    from mirrorsim.errors import BadParameter, OutputError
    from solver.errors import SolverError
    from solver.measurements import BeaconMeasurement, Sigma

    scene = ms.load_scene(ROOT / "scenes" / "exp1.yaml")
    # no writing into a folder of the user's files, nor over the run's own input
    user = tmp_path / "user"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    for run in (lambda: ms.render(scene, user), lambda: ms.evaluate(scene, user),
                lambda: ms.budget(scene, user), lambda: ms.track(scene, user, steps=1)):
        with pytest.raises(OutputError, match="did not write"):
            run()
    assert sorted(p.name for p in user.iterdir()) == ["notes.txt"]
    inside = tmp_path / "run"
    inside.mkdir()
    shutil.copy(ROOT / "scenes" / "exp1.yaml", inside / "exp1.json")
    with pytest.raises(OutputError, match="holds this run's input scene"):
        ms.evaluate(ms.load_scene(inside / "exp1.json"), inside)
    assert sorted(p.name for p in inside.iterdir()) == ["exp1.json"]
    # measurements no solve can use, and values of the wrong type, in one line
    truth = ms.check(scene).exact_measurements()
    b = truth.beacons[0]
    with pytest.raises(BadParameter, match="alpha_deg: nan is not a finite number"):
        BeaconMeasurement(b.position, float("nan"), b.d_total)
    with pytest.raises(SolverError, match="outside"):
        ms.solve(truth.observer, truth.beacons, [(truth.targets[0][0], 1e7)], sigma=Sigma())
    with pytest.raises(BadParameter, match=r"^beacons: .* is not a list of BeaconMeasurements"):
        ms.solve(truth.observer, [(b.position, b.alpha_deg, b.d_total)], truth.targets)
    with pytest.raises(BadParameter, match=r"^targets: .* is not a list of tuples"):
        ms.solve(truth.observer, truth.beacons, [truth.targets[0][1]])
    import numpy as np

    zero_d = ms.BeaconMeasurement(b.position, np.array(b.alpha_deg), b.d_total)  # a number
    assert ms.solve(truth.observer, [zero_d], truth.targets).target == pytest.approx(
        scene.target.position, abs=1e-6)
    for odd in ("66", None):  # None was a TypeError inside numpy
        with pytest.raises(BadParameter, match="alpha_deg: .* is not a number"):
            ms.BeaconMeasurement(b.position, odd, b.d_total)
    with pytest.raises(BadParameter, match="sigma: .* is not a Sigma or an ObjectSigmas"):
        ms.solve(truth.observer, truth.beacons, truth.targets, sigma={"alpha_deg": 0.01})
    with pytest.raises(BadParameter, match="calibration: .* is not a SelfCalibration"):
        ms.solve(truth.observer, truth.beacons, truth.targets, sigma=None, calibration={})
    with pytest.raises(BadParameter, match="nuisances: 'pan' .* is not a tuple of strings"):
        ms.SelfCalibration("pan")
    out = tmp_path / "out"
    with pytest.raises(BadParameter, match="calibration: .* is not a SelfCalibration"):
        ms.evaluate(scene, out, calibration={"nuisances": ["pan"]})
    with pytest.raises(BadParameter, match="keep"):
        ms.evaluate(scene, out, keep=("annotate",))
    # a one-beacon scene cannot carry a self-calibrated budget: refused, not an empty column
    with pytest.raises(BadParameter, match="nuisances"):
        ms.budget(scene, out, calibration=ms.SelfCalibration(("pan",)))
    with pytest.raises(BadParameter, match="position_sigma"):
        ms.track(scene, out, steps=1, position_sigma=0.5)
    # a dataset's parameters, before its folder is claimed
    for bad in ({"n": 2.5}, {"workers": 0}, {"seed": -1}, {"spp": 0}, {"sampler": "sobol"},
                {"executor": "slurm"}, {"keep": ("annotate",)}):
        with pytest.raises(BadParameter):
            ms.generate_dataset(**{"n": 2, "seed": 1, "out": tmp_path / "ds", **bad})
    # values a script edits in are held to the same rules as a file's
    from dataclasses import replace

    with pytest.raises(BadParameter, match="plain file name"):
        replace(scene, name="/".join(("..", "escaped")))
    with pytest.raises(BadParameter, match="whole number"):
        scene.with_render(spp=4.5)
    for bad in ({"particles": 0}, {"particles": 10**9}, {"steps": 2.5}, {"seed": -1}):
        with pytest.raises(BadParameter):
            ms.track(scene, out, **{"steps": 1, **bad})
    from mirrorsim.errors import InputError
    from solver.measurements import ObjectSigmas

    with pytest.raises(BadParameter, match="beacon σ pairs"):  # was taken for the first's
        ms.plan(scene, ObjectSigmas(Sigma(), (Sigma(), Sigma(0.02))))
    with pytest.raises(InputError, match="capture"):  # a path is read, not an AttributeError
        ms.detect(tmp_path / "f.png", tmp_path / "f.capture.json")
    from mirrorsim.pipelines.calibrate import calibrate

    for bad in (float("nan"), "1", 500.0):  # NaN failed deep inside a format
        with pytest.raises(BadParameter, match="distance_error"):
            calibrate(scene.camera, scene.target.size, scene.beacons[0].height,
                      distance_error=bad)
    assert not out.exists() and not (tmp_path / "ds").exists()


def test_a_scene_edited_in_a_script_is_built_as_its_file_would_be(tmp_path):
    """`dataclasses.replace` turned the mirror and left the target panel facing where the
    old mirror had put it (sweep_yaw.py did so): `edit_scene` recomputes it and runs the
    file's checks, and the entry points refuse a scene whose facing is stale, or whose
    edit a scene file would refuse, before anything is written."""
    from dataclasses import replace

    from mirrorsim.errors import BadParameter, SceneError

    base = ms.load_scene(ROOT / "scenes" / "default.yaml")
    turned = ms.edit_scene(base, {"name": "yaw25", "mirror": {"yaw": 25}})
    assert (turned.name, turned.mirror.yaw) == ("yaw25", 25)
    # the panel faces the camera's virtual image in the turned mirror: the camera
    # reflected across the mirror's line, by hand
    import numpy as np

    yaw = np.radians(25.0)
    normal = np.array([-np.sin(yaw), np.cos(yaw)])
    cam, centre = np.array(base.camera.position), np.array(base.mirror.center)
    virtual = cam - 2 * ((cam - centre) @ normal) * normal
    to_virtual = virtual - np.array(base.target.position)
    facing = np.degrees(np.arctan2(to_virtual[1], to_virtual[0]))
    assert turned.target.facing_deg == pytest.approx(facing, abs=1e-9)
    assert abs(turned.target.facing_deg - base.target.facing_deg) > 1.0
    assert turned.source == base.source and turned.render == base.render
    # a change the file's checks refuse, naming its key
    with pytest.raises(SceneError, match=r"\(edited\): mirror\.yawn: unknown key"):
        ms.edit_scene(base, {"mirror": {"yawn": 25}})
    with pytest.raises(SceneError, match="mirror.center"):
        ms.edit_scene(base, {"mirror": {"center": [500, 10]}})
    with pytest.raises(BadParameter, match="changes"):
        ms.edit_scene(base, [("mirror", {"yaw": 25})])
    assert ms.edit_scene(base, {"mirror": {"yaw": np.int64(25)}}).mirror.yaw == 25  # np.arange
    assert ms.edit_scene(base, {"mirror": {"yaw": np.array(25.0)}}).mirror.yaw == 25
    with pytest.raises(BadParameter, match=r"scene: .* is not a Scene \(read one with "
                       r"ms\.load_scene\(path\)\)"):
        ms.edit_scene(str(ROOT / "scenes" / "default.yaml"), {"mirror": {"yaw": 25}})
    assert ms.edit_scene(base, {"mirror": {"center": np.array([30.0, 62.0])}}).mirror.center \
        == (30.0, 62.0)
    # a one-beacon scene given a list of beacons takes the list
    pencil = {"height": base.beacons[0].height}
    two = ms.edit_scene(base, {"beacons": [{"position": list(base.beacons[0].position),
                                            **pencil}, {"position": [36, 53], **pencil}]})
    assert len(two.beacons) == 2
    with pytest.raises(BadParameter, match="give `beacons`"):  # it replaced the whole list
        ms.edit_scene(two, {"beacon": {"position": [36, 53], **pencil}})
    # each dataclass holds its values to what they can be when made, by an edit too
    with pytest.raises(BadParameter, match=r"size\[0\]: -5 must be > 0"):
        replace(base.mirror, size=(-5.0, 20.0))
    with pytest.raises(BadParameter, match="height: nan is not a finite number"):
        replace(base.beacons[0], height=float("nan"))
    with pytest.raises(BadParameter, match=r"hfov: 185 must be within \(0, 180\)"):
        replace(base.camera, hfov=185.0)
    with pytest.raises(BadParameter, match="scene.beacons: expected at least one beacon"):
        replace(base, beacons=())
    # the file's limits on a scene are the composer's: a camera the renderer widens for a
    # lens (sensor.distortion_canvas) may exceed them, a scene may not
    from mirrorsim.camera.sensor import distortion_canvas

    wide = replace(base.camera, resolution=(7680, 4320))
    canvas, margin = distortion_canvas(wide, (-0.02, 0.0))
    assert canvas.width == 7680 + 2 * margin > 7680
    for bad, key in ((replace(base, name="a" * 100), "name"),
                     (replace(base, name="tall", beacons=(replace(base.beacons[0],
                                                                  height=250.0),)),
                      r"beacon\.height: 250 must be ≤ 200"),
                     (replace(base, name="wide", camera=replace(base.camera, hfov=175.0)),
                      "camera.hfov: 175 must be ≤ 170")):
        with pytest.raises(SceneError, match=key):
            ms.evaluate(bad, tmp_path / "bad")
    # a bench value out of its bounds, or beyond what the mirror allows, is the composer's
    pitched = replace(base, name="pitched", bench=replace(base.bench, pitch=25.0))
    curved = replace(base, name="curved", bench=replace(base.bench, curvature_radius=3.0))
    for bad, key in ((pitched, "camera.pitch"), (curved, "mirror.curvature_radius")):
        with pytest.raises(SceneError, match=rf"\(edited\): {key}: "):
            ms.evaluate(bad, tmp_path / "bad")
        assert not (tmp_path / "bad").exists()
    stale = replace(base, name="stale", mirror=replace(base.mirror, yaw=25))
    off = replace(base, name="off", mirror=replace(base.mirror, center=(500.0, 10.0)))
    out = tmp_path / "out"
    for run in (ms.render, ms.evaluate, ms.budget, lambda s, o: ms.track(s, o, steps=1),
                lambda s, _o: ms.plan(s)):
        with pytest.raises(BadParameter, match="target panel's facing no longer follows"):
            run(stale, out)
        with pytest.raises(SceneError, match="mirror.center"):
            run(off, out)
    for run in (ms.check, lambda s: ms.evaluate(s, out)):  # a path for a scene: one line
        with pytest.raises(BadParameter, match="is not a Scene"):
            run(str(ROOT / "scenes" / "default.yaml"))
    assert not out.exists()
    assert ms.plan(turned).best is not None  # an edited scene is an ordinary one
