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
    cal = ms.solve(many.observer, many.beacons, many.targets, None,
                   ms.SelfCalibration(("pan", "scale")))
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
