"""Datasets: end to end, determinism across workers, resume after a kill, Dask, and the
error model's fit."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mirrorsim.cli.main import main
from mirrorsim.pipelines import error_features, errormodel
from mirrorsim.pipelines.dataset import collect_rows, run_dataset
from mirrorsim.pipelines.scenes import load_scene
from solver.selfcal import SelfCalibration
from tests.conftest import synthetic_columns

SPEC = Path(__file__).parent / "data" / "tiny_spec.yaml"
VOLATILE = ("seconds_total", "seconds_sample", "traceback")


def _stable(rows):
    """Rows without their timings; every row must be a success (identical failures
    would otherwise compare equal)."""
    assert rows and all(r.error == "" for r in rows), [r.error for r in rows]
    return [{k: v for k, v in r.columns.items() if k not in VOLATILE} for r in rows]


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds") / "a"
    res = run_dataset(3, 3, out, workers=1, spec_path=SPEC, progress=False)
    return out, res


def test_tiny_dataset_end_to_end(one_worker):
    out, res = one_worker
    assert res.rows == 3 and res.computed == 3 and res.failed == 0
    import pyarrow.parquet as pq

    table = pq.read_table(out / "dataset.parquet").to_pydict()
    assert table["index"] == [0, 1, 2]
    assert table["error"] == ["", "", ""]
    # the table holds exactly the declared columns, and the card names each of them
    from mirrorsim.formats.dataset_table import NAMES, PER_OBJECT

    assert sorted(table) == sorted(NAMES)
    card = (out / "README.md").read_text()
    assert "dataset.parquet" in card
    flat = " ".join(card.split())
    for name in NAMES:
        per_object = name.split("_", 1)[-1] if name.startswith(("target_", "beacon_")) \
            and name.split("_", 1)[-1] in {c.name for c in PER_OBJECT} else None
        assert f"`{'<object>_' + per_object if per_object else name}`" in flat, name
    # by default a frame's PNG, truth and capture record, and the measurements the solver
    # saw (no ids, no annotated)
    assert sorted(f.name for f in (out / "frames" / "scene000000").iterdir()) == [
        "scene000000.capture.json", "scene000000.json", "scene000000.measurements.json",
        "scene000000.png"]
    # every row's scene is a normal scene file that loads on its own
    for i in range(3):
        s = load_scene(out / "scenes" / f"scene{i:06d}.yaml")
        assert s.render.seed == i and s.camera.resolution == (960, 544)


def test_same_rows_whatever_the_workers(one_worker, tmp_path):
    out, _ = one_worker
    # a memory limit every worker passes at once: each retires after one scene, which
    # exercises the replacement of worker processes too
    run_dataset(3, 3, tmp_path / "b", workers=2, spec_path=SPEC, progress=False,
                max_rss_mb=1)
    a, b = _stable(collect_rows(out, 3)), _stable(collect_rows(tmp_path / "b", 3))
    assert a == b, [{k: (x[k], y.get(k)) for k in x if x[k] != y.get(k)}
                    for x, y in zip(a, b, strict=True)]


def test_keep_writes_the_optional_files(one_worker, tmp_path):
    out, _ = one_worker
    assert main(["dataset", "--n", "1", "--seed", "3", "--out", str(tmp_path / "k"),
                 "--spec", str(SPEC), "--keep", "ids", "annotated", "--workers", "1",
                 "--quiet"]) == 0
    names = {f.name for f in (tmp_path / "k" / "frames" / "scene000000").iterdir()}
    assert {"scene000000.ids.png", "scene000000.annotated.png"} <= names
    # the same row as without them
    assert (_stable(collect_rows(tmp_path / "k", 1))
            == _stable(collect_rows(out, 3))[:1])


def test_existing_folder_needs_resume(one_worker, capsys):
    out, _ = one_worker
    assert main(["dataset", "--n", "3", "--seed", "3", "--out", str(out), "--spec", str(SPEC),
                 "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(["dataset", "--n", "3", "--seed", "8", "--out", str(out), "--spec", str(SPEC),
                 "--resume", "--quiet"]) == 2  # other settings


def test_resume_after_kill(one_worker, tmp_path):
    """kill -9 the whole run after its first finished row, then --resume: no row lost,
    none duplicated, and the rows are those of an uninterrupted run."""
    out, _ = one_worker
    dst = tmp_path / "k"
    cmd = [sys.executable, "-m", "mirrorsim", "dataset", "--n", "3", "--seed", "3",
           "--out", str(dst), "--spec", str(SPEC), "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and not list((dst / "rows").glob("*.json")):
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert subprocess.run(cmd + ["--resume"]).returncode == 0
    rows = collect_rows(dst, 3)
    assert [r["index"] for r in rows] == [0, 1, 2]
    assert _stable(rows) == _stable(collect_rows(out, 3))
    assert not list((dst / "rows").glob(".*tmp*"))


def test_dask_local_cluster_gives_the_same_rows(one_worker, tmp_path):
    pytest.importorskip("dask.distributed")
    out, _ = one_worker
    run_dataset(2, 3, tmp_path / "d", executor="dask", spec_path=SPEC, progress=False)
    assert _stable(collect_rows(tmp_path / "d", 2)) == _stable(collect_rows(out, 3)[:2])


def test_error_model_bias_recovers_a_known_law():
    """Synthetic rows with α error ~ N(0.001 + 2e-5·d, 0.002) and d error ~ N(−0.001,
    0.003): the diagnostic bias fit finds those coefficients, and the σ law (about the
    truth: the bias is part of the spread) the RMS."""
    n = 4000
    cols = synthetic_columns(n, 0)
    rng = np.random.default_rng(0)
    for kind in ("target", "beacon"):
        d = np.asarray(cols[f"{kind}_d_true"])
        # heights drawn apart from d: 1/height and d would be collinear otherwise, and the
        # fit would share the slope between them
        cols[f"{kind}_height_px_true"] = rng.uniform(40, 300, n)
        cols[f"{kind}_alpha_err"] = rng.normal(0.001 + 2e-5 * d, 0.002)
        cols[f"{kind}_d_rel_err"] = rng.normal(-0.001, 0.003, n)
    model = errormodel.fit(cols)
    a = model.fits["target"]["alpha"]
    assert a.bias[1] == pytest.approx(2e-5, abs=4e-6)
    r = model.fits["beacon"]["d_rel"]
    assert r.bias[0] == pytest.approx(-0.001, abs=4e-4)
    assert r.typical_sigma == pytest.approx(np.hypot(0.001, 0.003), rel=0.08)


def test_error_model_fits_a_signed_off_axis_bias_through_outliers():
    """α bias = 0.003°·(off-axis/10°) changes sign across the axis; σ = 0.002°; 3 % of the
    rows are gross errors of ±0.5°.  The signed, robust fit recovers the slope, and the
    gross errors are counted apart, not fitted."""
    n = 3000
    cols = synthetic_columns(n, 1)
    rng = np.random.default_rng(1)
    for kind in ("target", "beacon"):
        off = np.asarray(cols[f"{kind}_off_axis_deg"])
        err = 0.0003 * off + rng.normal(0, 0.002, n)
        gross = rng.random(n) < 0.03
        err[gross] += rng.choice([-0.5, 0.5], gross.sum())
        cols[f"{kind}_alpha_err"] = err
    model = errormodel.fit(cols)
    a = model.fits["target"]["alpha"]
    assert error_features.FEATURES[2] == "off_axis_deg"
    assert a.bias[2] == pytest.approx(0.0003, rel=0.05)
    assert a.gross_errors == pytest.approx(0.03 * n, rel=0.25)
    assert a.typical_sigma < 0.02  # the ±0.5° errors left out of the σ


def test_errormodel_command_on_a_dataset(one_worker, tmp_path, capsys):
    out, _ = one_worker
    # three rows are too few: a clear refusal, saying how many it needs
    assert main(["errormodel", str(out)]) == 2
    err = capsys.readouterr().err
    assert "too few usable rows (3)" in err and "30 needed" in err
    # a model file feeds solve/montecarlo/plan
    cols = synthetic_columns(50, 1, sigma_alpha=(0.004, 0.004), sigma_d=(0.005, 0.005))
    model_path = tmp_path / "m.json"
    errormodel.write_model(errormodel.fit(cols), model_path)
    assert main(["montecarlo", "--error-model", str(model_path)]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 7  # a 4th row
    meas = tmp_path / "meas.json"
    main(["check", str(Path(__file__).parents[1] / "scenes" / "exp1.yaml"),
          "--measurements", str(meas)])
    assert main(["solve", str(meas), "--error-model", str(model_path), "--json", "-"]) == 0
    printed = capsys.readouterr().out
    assert "covariance" in json.loads(printed[printed.index("{"):])


def test_bad_spec_is_refused_with_its_key(tmp_path, capsys):
    bad = tmp_path / "spec.yaml"
    bad.write_text(SPEC.read_text().replace("yaw: [5, 35]", "yaw: [35, 5]"))
    assert main(["dataset", "--n", "1", "--seed", "0", "--out", str(tmp_path / "o"),
                 "--spec", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "mirror.yaw" in err and "low end" in err and not (tmp_path / "o").exists()


def test_a_killed_worker_is_replaced(one_worker, tmp_path):
    """kill -9 one worker process mid-run: the run itself carries on and completes."""
    out, _ = one_worker
    dst = tmp_path / "w"
    cmd = [sys.executable, "-m", "mirrorsim", "dataset", "--n", "3", "--seed", "3",
           "--out", str(dst), "--spec", str(SPEC), "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, start_new_session=True, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    victim = None
    while time.time() < deadline and victim is None and proc.poll() is None:
        kids = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True,
                              text=True).stdout.split()
        workers = [k for k in kids if "spawn_main" in Path(f"/proc/{k}/cmdline").read_text(
            errors="ignore")] if kids else []
        if workers and (dst / "scenes").exists() and list((dst / "scenes").glob("*.yaml")):
            victim = int(workers[0])
        time.sleep(0.2)
    assert victim is not None
    os.kill(victim, signal.SIGKILL)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0
    assert "a worker process died" in err
    assert _stable(collect_rows(dst, 3)) == _stable(collect_rows(out, 3))


def test_camera_models_are_calibrated_once_before_the_workers(tmp_path):
    """A spec with camera models: every model is calibrated up front (a one-scene
    dataset leaves both models' K in the cache, though its scene uses one), and every
    scene's camera is one of the models."""
    import yaml

    from mirrorsim.formats.cache import read_entry
    from mirrorsim.pipelines.calibrate import calibration_key
    from mirrorsim.pipelines.random_scenes import camera_models, load_spec

    spec = yaml.safe_load(SPEC.read_text())
    for k in ("height", "hfov"):
        spec["camera"].pop(k)
    spec["camera"]["models"] = [{"height": 5.5, "hfov": 65.2}, {"height": 7.5, "hfov": 62}]
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    cams = camera_models(load_spec(path))
    assert [c.resolution for c in cams] == [(960, 544)] * 2  # the camera block's default
    keys = [calibration_key(c, (9.9, 15.25), 4.2) for c in cams]
    run_dataset(1, 1, tmp_path / "one", workers=1, spec_path=path, progress=False)
    assert all(read_entry("calibration", k) is not None for k in keys)
    run_dataset(3, 1, tmp_path / "d", workers=1, spec_path=path, progress=False)
    for i in range(3):
        cam = load_scene(tmp_path / "d" / "scenes" / f"scene{i:06d}.yaml").camera
        assert (cam.height, cam.hfov) in {(5.5, 65.2), (7.5, 62.0)}


# ------------------------------------------------------------- bench imperfections

def _bench_spec(tmp_path, bench: dict) -> Path:
    import yaml

    spec = yaml.safe_load(SPEC.read_text())
    spec["bench"] = bench
    path = tmp_path / "bench_spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_a_dataset_draws_bench_imperfections_and_its_rows_carry_them(one_worker, tmp_path):
    """Pan error and calibration distance error drawn per scene, on the ideal dataset's
    scenes (same seed: the bench block is drawn from a stream of its own, and neither changes
    the photograph).  Against the same scene's ideal row: the α error moves by the pan
    error (the mount's report is off by it), and the d_total error by the calibration's
    scale, −(d − f)/d · e/(100 + e − f) (K measured at 100 + e while 100 is assumed; f
    the face offset), within the calibration's own measurement error at half size (a
    pencil 100 cm off is a few dozen px: its K varies by ~0.5 % with the distance)."""
    from mirrorsim.scene.model import FRONT_OFFSET

    ideal = collect_rows(one_worker[0], 3)
    spec = _bench_spec(tmp_path, {"camera": {"pan_error": [-0.5, 0.5]},
                                  "calibration": {"distance_error": [-2, 2]}})
    out = tmp_path / "d"
    res = run_dataset(3, 3, out, workers=1, spec_path=spec, progress=False)
    assert res.failed == 0
    rows = collect_rows(out, 3)
    pans = [r["bench_pan_error_deg"] for r in rows]
    assert len(set(pans)) == 3 and all(-0.5 <= p <= 0.5 for p in pans)
    for r, r0 in zip(rows, ideal, strict=True):
        assert r0["bench_pan_error_deg"] == 0.0 and r0["bench_calibration_error_cm"] == 0.0
        assert r["bench_pitch_deg"] == 0.0 and r["bench_curvature_per_cm"] == 0.0
        assert r["target_d_true"] == r0["target_d_true"]  # the same scene
        for kind in ("target", "beacon"):
            assert r[f"{kind}_alpha_err"] - r0[f"{kind}_alpha_err"] == pytest.approx(
                r["bench_pan_error_deg"], abs=1e-6)
            e, d, f = r["bench_calibration_error_cm"], r[f"{kind}_d_true"], FRONT_OFFSET[kind]
            assert r[f"{kind}_d_rel_err"] - r0[f"{kind}_d_rel_err"] == pytest.approx(
                -(d - f) / d * e / (100 + e - f), abs=0.002 if kind == "target" else 0.008)
        # the scene file keeps what was drawn
        s = load_scene(out / "scenes" / f"{r['scene']}.yaml")
        assert s.bench.pan_error == r["bench_pan_error_deg"]
        assert s.bench.calibration_distance_error == r["bench_calibration_error_cm"]
    assert "bench_pan_error_deg" in (out / "README.md").read_text()


def test_a_spec_without_a_bench_draws_the_same_scenes_as_before(tmp_path):
    """The bench block is drawn from its own stream: adding it keeps every scene's geometry."""
    from mirrorsim.pipelines.random_scenes import load_spec, sample_scene

    plain = load_spec(SPEC)
    bench = load_spec(_bench_spec(tmp_path, {"mirror": {"tilt": [-1, 1]}}))
    for i in range(3):
        a, b = sample_scene(plain, i, "s"), sample_scene(bench, i, "s")
        assert a.mirror == b.mirror and a.target == b.target and a.camera == b.camera
        assert a.bench.tilt == 0.0 and -1 <= b.bench.tilt <= 1 and b.bench.tilt != 0.0


@pytest.mark.parametrize("bench, key", [
    ({"mirror": {"tilt": [0, 50]}}, "bench.mirror.tilt"),
    ({"mirror": {"curvature": [0, 0.1]}}, "bench.mirror.curvature"),  # R = 10 cm < the mirror
    ({"camera": {"jpeg_quality": [0, 90]}}, "bench.camera.jpeg_quality"),
    ({"camera": {"noise": {"full_well": 5000, "read_noise": [-1, 3]}}}, "bench.camera.noise"),
    ({"camera": {"pan_eror": 0.5}}, "bench.camera.pan_eror"),
    ({"beacon": {"known_position_offset": [0, 200]}}, "bench.beacon.known_position_offset"),
    ({"calibration": {"distance_error": [1, -1]}}, "bench.calibration.distance_error"),
])
def test_bad_bench_ranges_are_refused_with_their_key(tmp_path, capsys, bench, key):
    spec = _bench_spec(tmp_path, bench)
    assert main(["dataset", "--n", "1", "--seed", "0", "--out", str(tmp_path / "o"),
                 "--spec", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert key in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_error_model_fits_bias_against_bench_imperfections():
    """Synthetic rows on a bench: α error = pan error + N(0, 0.003°); d_total error =
    −0.0102·(calibration error) − mirror power + N(0, 0.002).  The fit recovers the
    coefficients 1, −0.0102 and −1 by the features' names; the pan error, shared by a
    row's two α's, is the model's shared offset (uniform in ±0.5°: σ ≈ 0.29°), and each
    image's own α σ the rows' own noise."""
    rng = np.random.default_rng(2)
    n = 3000
    cols = synthetic_columns(n, 2)
    zeros = np.zeros(n)
    cols.update({"bench_pan_error_deg": rng.uniform(-0.5, 0.5, n),
                 "bench_calibration_error_cm": rng.uniform(-2, 2, n),
                 "bench_curvature_per_cm": rng.uniform(-1e-3, 1e-3, n),
                 "bench_distortion_known": np.ones(n, bool)})
    for c in ("bench_pitch_deg", "bench_roll_deg", "bench_k1", "bench_k2", "bench_full_well",
              "bench_read_noise", "bench_jpeg_quality", "bench_tilt_deg"):
        cols[c] = zeros
    for kind in ("target", "beacon"):
        d1, d2 = rng.uniform(30, 70, n), rng.uniform(10, 50, n)
        inc = rng.uniform(0, 60, n)
        power = 2 * np.cos(np.radians(inc)) * d1 * d2 * cols["bench_curvature_per_cm"] / (d1 + d2)
        cols.update({f"{kind}_d_true": d1 + d2, f"{kind}_d1": d1, f"{kind}_d2": d2,
                     f"{kind}_off_axis_deg": rng.uniform(-20, 20, n),
                     f"{kind}_incidence_deg": inc,
                     f"{kind}_height_px_true": 15000 / (d1 + d2),
                     f"{kind}_alpha_err": cols["bench_pan_error_deg"] + rng.normal(0, 0.003, n),
                     f"{kind}_d_rel_err": (-0.0102 * cols["bench_calibration_error_cm"] - power
                                           + rng.normal(0, 0.002, n))})
    model = errormodel.fit(cols)
    names = model.bias_features
    assert set(names) - set(error_features.FEATURES) == {"pan_error_deg", "calibration_error_cm",
                                                      "mirror_power"}
    for kind in ("target", "beacon"):
        a, d = model.fits[kind]["alpha"], model.fits[kind]["d_rel"]
        assert a.bias[names.index("pan_error_deg")] == pytest.approx(1.0, abs=0.01)
        assert d.bias[names.index("calibration_error_cm")] == pytest.approx(-0.0102, abs=5e-4)
        assert d.bias[names.index("mirror_power")] == pytest.approx(-1.0, abs=0.1)
    # the shared parts (the pan, the calibration, the curvature) are the solver's
    # nuisances, not each image's σ: the own errors are the rows' own noise (0.003°,
    # 0.2 %), and no shared α offset is left in them
    assert model.shared_alpha_deg == 0.0
    for typical in (model.typical.target, model.typical.beacons[0]):
        assert typical.alpha_deg == pytest.approx(0.003, rel=0.25)
        assert typical.d_total_rel == pytest.approx(0.002, rel=0.25)


@pytest.mark.parametrize("damage", ["misspelt column", "edited value", "truncated",
                                    "another scene's", "no checksum", "other settings"])
def test_resume_redoes_a_row_that_fails_verification(one_worker, tmp_path, damage):
    """A row file edited, truncated, copied from another scene or from before rows were
    sealed, or sealed by a dataset of the same seed and other settings (its digest of
    them differs): moved to rows/rejected/ with a warning and redone, to the same row."""
    import json
    import shutil

    from mirrorsim.formats.cache import seal

    out, _ = one_worker
    dst = tmp_path / "copy"
    shutil.copytree(out, dst)
    row = dst / "rows" / "scene000001.json"
    good = json.loads(row.read_text())
    bad = {k: v for k, v in good.items() if k != "sha256"}
    text = {"misspelt column": json.dumps(seal({**bad, "target_alpha_eror": 1.0})),
            "edited value": json.dumps({**good, "err_target_cm": 0.0}),
            "truncated": row.read_text()[:100],
            "another scene's": (dst / "rows" / "scene000002.json").read_text(),
            "no checksum": json.dumps(bad),
            "other settings": json.dumps(seal({**bad, "dataset": "0" * 16}))}[damage]
    row.write_text(text)
    with pytest.warns(RuntimeWarning, match="scene000001.json.*not trusted"):
        run = run_dataset(3, 3, dst, workers=1, spec_path=SPEC, progress=False, resume=True)
    assert (run.computed, run.already_done) == (1, 2)
    assert (dst / "rows" / "rejected" / "scene000001.json").read_text() == text  # kept
    assert _stable(collect_rows(dst, 3)) == _stable(collect_rows(out, 3))


# ------------------------------------------------ a table that is not fitted blindly


def _table_cases():
    import pyarrow as pa
    import pyarrow.parquet as pq

    from mirrorsim.formats.dataset_folder import write_table
    from mirrorsim.formats.dataset_table import DatasetRow

    def truncated(ds):
        p = ds / "dataset.parquet"
        p.write_bytes(p.read_bytes()[:300])

    def edited(ds):  # a value changed, the metadata (and its checksum) kept
        p = ds / "dataset.parquet"
        t = pq.read_table(p)
        i = t.schema.get_field_index("err_target_cm")
        t = t.set_column(i, "err_target_cm", pa.array([0.0] * t.num_rows))
        pq.write_table(t, p)

    def column_dropped(ds):
        p = ds / "dataset.parquet"
        t = pq.read_table(p)
        pq.write_table(t.drop_columns(["target_alpha_err"]), p)

    def no_rows(ds):
        write_table(ds, [])

    def all_failed(ds):
        rows = collect_rows(ds, 3)
        write_table(ds, [DatasetRow({k: r[k] for k in ("index", "scene", "seed", "schema")}
                                    | {"error": "DetectionError: nothing seen"}) for r in rows])

    def folder(ds):
        (ds / "dataset.parquet").unlink()
        (ds / "dataset.parquet").mkdir()

    return [(truncated, "not a readable Parquet table"), (edited, "checksum"),
            (column_dropped, "checksum"), (no_rows, "holds no rows"),
            (all_failed, "all 3 rows failed"), (folder, "not a file")]


@pytest.mark.parametrize("case", range(6))
def test_errormodel_refuses_a_table_it_cannot_trust(one_worker, tmp_path, capsys, case):
    """Truncated, edited, a column short, empty, all failed, or a folder: exit 2 with one
    line, and no model written."""
    import shutil

    from mirrorsim.cli.main import main

    damage, says = _table_cases()[case]
    ds = tmp_path / "ds"
    shutil.copytree(one_worker[0], ds)
    damage(ds)
    assert main(["errormodel", str(ds)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "dataset.parquet" in err and says in err, err
    assert not (ds / "error_model.json").exists()


def test_the_table_a_dataset_writes_verifies(one_worker):
    from mirrorsim.formats.dataset_folder import read_table

    assert read_table(one_worker[0])["index"] == [0, 1, 2]


def test_errormodel_refuses_a_dataset_whose_row_files_no_longer_verify(one_worker, tmp_path,
                                                                        capsys):
    """The table is fitted only while it is its verified rows: a row file stubbed since
    the table was written is found (resuming redoes that scene)."""
    import shutil

    from mirrorsim.cli.main import main

    ds = tmp_path / "ds"
    shutil.copytree(one_worker[0], ds)
    (ds / "rows" / "scene000001.json").write_text("{}")
    assert main(["errormodel", str(ds)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "scene000001.json: not a row of this dataset" in err, err
    (ds / "rows" / "scene000001.json").unlink()
    assert main(["errormodel", str(ds)]) == 2
    assert "its rows differ from the row files" in capsys.readouterr().err


def test_load_dataset_gives_a_dataframe_with_the_files(one_worker):
    """`mirrorsim.load_dataset`: the verified table as a DataFrame, each row with its
    frame and measurements file; pandas alone reads the same Parquet columns."""
    import pandas as pd

    import mirrorsim as ms

    out, _ = one_worker
    df = ms.load_dataset(out)
    assert len(df) == 3 and df["index"].tolist() == [0, 1, 2]
    assert all(Path(p).exists() for p in df["frame"]) and all(
        Path(p).exists() for p in df["measurements_file"])
    plain = pd.read_parquet(out / "dataset.parquet")
    assert set(plain.columns) <= set(df.columns)
    assert df["target_mahalanobis"].notna().all()


def test_resume_with_a_larger_n_extends_the_dataset_with_the_same_scenes(one_worker,
                                                                         tmp_path):
    """The 3-scene dataset's first two rows, resumed with n = 3, compute only the third,
    whose row is the one a 3-scene run made; a smaller n is refused, and the folder's
    description records the new n."""
    import json
    import shutil

    from mirrorsim.formats.dataset_folder import DatasetError

    out, _ = one_worker
    dst = tmp_path / "grow"
    shutil.copytree(out, dst)
    (dst / "rows" / "scene000002.json").unlink()
    meta = json.loads((dst / "dataset.json").read_text())
    (dst / "dataset.json").write_text(json.dumps({**meta, "n": 2}))  # as a 2-scene run left it
    run = run_dataset(3, 3, dst, workers=1, spec_path=SPEC, progress=False, resume=True)
    assert (run.computed, run.already_done, run.rows) == (1, 2, 3)
    assert json.loads((dst / "dataset.json").read_text())["n"] == 3
    assert _stable(collect_rows(dst, 3)) == _stable(collect_rows(out, 3))
    with pytest.raises(DatasetError, match="holds 3 scenes: resume it with n ≥ 3"):
        run_dataset(2, 3, dst, workers=1, spec_path=SPEC, progress=False, resume=True)


def _spec_with(tmp_path, **beacon) -> Path:
    import yaml

    d = yaml.safe_load(SPEC.read_text())
    d["beacon"].update(beacon)
    path = tmp_path / f"spec_{'_'.join(f'{k}{v}' for k, v in beacon.items())}.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def test_a_spec_draws_several_beacons_each_whole(tmp_path):
    from mirrorsim.pipelines.random_scenes import load_spec, sample_scene
    from mirrorsim.truth import visibility

    plain, one, three = (load_spec(p) for p in (SPEC, _spec_with(tmp_path, count=1),
                                                  _spec_with(tmp_path, count=3)))
    for i in range(4):
        rng = lambda i=i: np.random.default_rng(np.random.SeedSequence(8, spawn_key=(i,)))  # noqa: E731
        # a spec of one beacon draws the scenes it drew before the key existed
        assert sample_scene(one, rng(), "s") == sample_scene(plain, rng(), "s")
        s = sample_scene(three, rng(), "s")
        assert len(s.beacons) == 3 and len({b.height for b in s.beacons}) == 1
        assert all(visibility.visibility(s, b).fraction == 1.0 for b in s.beacons)
        assert len({b.position for b in s.beacons}) == 3


@pytest.fixture(scope="module")
def three_beacons(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ds3")
    out = tmp / "d"
    # three beacons by the parameter (a spec's beacon.count does the same: the draws' test)
    res = run_dataset(2, 5, out, workers=1, spec_path=SPEC, beacons=3, progress=False,
                      calibration=SelfCalibration(("pan", "scale"), priors={"pan": 0.3}))
    return out, res


def test_a_dataset_of_several_beacons_self_calibrated(three_beacons):
    from mirrorsim.formats.dataset_folder import read_table
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines.uncertainty import validate

    out, res = three_beacons
    assert res.failed == 0
    cols = read_table(out)
    for i in range(2):
        scene = load_scene(out / "scenes" / f"scene{i:06d}.yaml")
        assert cols["beacons"][i] == 3 and cols["calibrate"][i] == "pan,scale"
        assert cols["calibrate_priors"][i] == "pan=0.3"
        for k, kind in enumerate(("beacon", "beacon2", "beacon3")):
            # each beacon's columns are its own: its position, and its own measurement
            assert (cols[f"{kind}_pos_x"][i], cols[f"{kind}_pos_y"][i]) == pytest.approx(
                scene.beacons[k].position)
            assert abs(cols[f"{kind}_alpha_err"][i]) < 0.05
            assert abs(cols[f"{kind}_d_rel_err"][i]) < 0.02
        # an ideal bench: the self-calibration finds no pan offset and no scale, to
        # within its own σ's
        assert abs(cols["est_pan_offset_deg"][i]) < 4 * cols["est_pan_offset_deg_sd"][i]
        assert abs(cols["est_range_scale"][i] - 1) < 4 * cols["est_range_scale_sd"][i]
        assert 0 < cols["est_pan_offset_deg_sd"][i] < 0.5
        assert cols["est_mirror_power_per_cm"][i] is None  # not estimated: null
    # the validation solves each row again as the dataset did: all three beacons,
    # self-calibrated with the same prior, with the same σ's (without the prior the
    # distances differ)
    v = validate(default_error_model(), cols)
    assert v.n_failed == 0
    assert v.mahalanobis == pytest.approx(cols["target_mahalanobis"], rel=1e-6)
    unprimed = {**cols, "calibrate_priors": ["", ""]}
    assert validate(default_error_model(), unprimed).mahalanobis != pytest.approx(
        cols["target_mahalanobis"], rel=1e-6)
    # and the frames: one per beacon; the card says how the rows were solved
    assert sorted(p.name for p in (out / "frames" / "scene000000").glob("*.png")) == [
        f"scene000000_b{k}.png" for k in range(3)]
    assert "--calibrate pan,scale --prior pan=0.3`" in (out / "README.md").read_text()


def test_a_dataset_resumes_only_with_its_self_calibration(three_beacons, tmp_path):
    import shutil

    from mirrorsim.formats.dataset_folder import DatasetError

    out, _ = three_beacons
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    same = SelfCalibration(("pan", "scale"), priors={"pan": 0.3})
    for other in (SelfCalibration(), SelfCalibration(("pan",)),
                  SelfCalibration(("pan", "scale")),
                  SelfCalibration(("pan", "scale"), priors={"pan": 0.2})):
        # what it was made with, in words (the library names no flag)
        with pytest.raises(DatasetError, match=r"other self-calibration settings "
                           r"\(nuisances pan, scale; priors pan=0.3\)"):
            run_dataset(3, 5, copy, workers=1, spec_path=SPEC, beacons=3, progress=False,
                        resume=True, calibration=other)
    # the beacon count is the spec's, and the refusal says which setting differs
    with pytest.raises(DatasetError, match=r"other settings: spec beacon.count 3 \(now 2\)"):
        run_dataset(3, 5, copy, workers=1, spec_path=SPEC, beacons=2, progress=False,
                    resume=True, calibration=same)


def test_a_row_of_the_older_layout_reads_as_one_plain_beacon():
    from mirrorsim.formats.dataset_table import NAMES, DatasetRow

    old = dict.fromkeys(NAMES, 0.0) | {"error": "", "schema": 2}
    for name in ("beacons", "calibrate", "calibrate_priors", "beacon_sigma", *(
            f"est_{k}{sd}" for k in ("pan_offset_deg", "range_scale", "mirror_power_per_cm")
            for sd in ("", "_sd"))):
        del old[name]
    row = DatasetRow.from_json(old)
    assert row["beacons"] == 1 and row["calibrate"] == "" and row["est_range_scale"] is None
    assert row["calibrate_priors"] == ""
    with pytest.raises(ValueError, match="missing"):  # a row of this layout must have them
        DatasetRow.from_json(old | {"schema": 3})
    # a row of schema 3 (self-calibration without priors) reads as one without them
    three = dict.fromkeys(NAMES, 0.0) | {"error": "", "schema": 3, "calibrate": "pan,scale"}
    del three["calibrate_priors"]
    assert DatasetRow.from_json(three)["calibrate_priors"] == ""
    with pytest.raises(ValueError, match="missing"):
        DatasetRow.from_json(three | {"schema": 4})
    # a row of schema 4 (no image features) reads with them unknown
    four = dict.fromkeys(NAMES, 0.0) | {"error": "", "schema": 4}
    del four["pencil_height_cm"], four["target_contrast"], four["beacon_height_px_meas"]
    row = DatasetRow.from_json(four)
    assert row["target_contrast"] is None and row["pencil_height_cm"] is None
    with pytest.raises(ValueError, match="missing"):
        DatasetRow.from_json(four | {"schema": 5})


def test_error_model_fits_every_beacon_image_and_the_target_once():
    from mirrorsim.formats import dataset_table as table

    n = 60
    cols = synthetic_columns(n, 4, sigma_alpha=(0.003, 0.003), sigma_d=(0.002, 0.005))
    other = synthetic_columns(n, 5, sigma_alpha=(0.003, 0.003), sigma_d=(0.002, 0.005))
    cols["beacons"] = [2] * (n - 10) + [1] * 10
    for name in table.PER_OBJECT:
        values = np.asarray(other[f"beacon_{name.name}"], float) if \
            f"beacon_{name.name}" in other else np.full(n, np.nan)
        cols[f"beacon2_{name.name}"] = np.where(np.arange(n) < n - 10, values, np.nan)
    for name in ("known_x", "known_y"):
        cols[f"beacon2_{name}"] = np.zeros(n)
    model = errormodel.fit(cols)
    assert model.fits["target"]["alpha"].n == n
    assert model.fits["beacon"]["alpha"].n == 2 * n - 10
    assert model.fits["beacon"]["d_rel"].typical_sigma == pytest.approx(0.005, rel=0.2)


def test_calibrate_needs_a_spec_whose_beacons_carry_it(tmp_path, capsys):
    out = tmp_path / "d"
    code = main(["dataset", "--n", "1", "--seed", "1", "--out", str(out), "--spec", str(SPEC),
                 "--calibrate", "pan,scale", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "--calibrate" in err and "beacon.count" in err and str(SPEC) in err
    assert not out.exists()
    assert main(["dataset", "--n", "1", "--seed", "1", "--out", str(out), "--beacons", "5",
                 "--quiet"]) == 2
    assert "--beacons: 5 must be within 1..4" in capsys.readouterr().err
    assert not out.exists()


def _as_layout(src, dst, schemas, drop):
    """A copy of dataset ``src`` as an older mirrorsim wrote it: each row of its schema
    without the columns ``drop`` (sealed again), and the table of those rows, sealed."""
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    from mirrorsim.formats.cache import checksum, seal, unseal
    from mirrorsim.formats.dataset_folder import TABLE_SEAL
    from mirrorsim.formats.files import jsonable

    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)
    for schema, p in zip(schemas, sorted((dst / "rows").glob("scene*.json")), strict=True):
        d = {k: v for k, v in unseal(json.loads(p.read_text()), p.name).items()
             if k not in drop}
        p.write_text(json.dumps(seal({**d, "schema": schema})))
    cols = {k: v for k, v in pq.read_table(dst / "dataset.parquet").to_pydict().items()
            if k not in drop}
    cols["schema"] = list(schemas)
    arrow = pa.table(cols)
    pq.write_table(arrow.replace_schema_metadata(
        {TABLE_SEAL: checksum(jsonable(arrow.to_pydict()))}), dst / "dataset.parquet")


def test_a_table_of_the_older_layout_is_read(one_worker, tmp_path):
    """A dataset made before several beacons and self-calibration (rows of schema 2, its
    table without their columns, sealed): read as one plain beacon; rows that say they
    are of a later layout without its columns are refused."""
    from mirrorsim.formats.dataset_folder import DatasetError, read_table
    from mirrorsim.formats.dataset_table import older_values

    out, _ = one_worker
    old = tmp_path / "old"
    _as_layout(out, old, [2, 2, 2], set(older_values(2)))
    read = read_table(old)
    assert read["beacons"] == [1, 1, 1] and read["calibrate"] == ["", "", ""]
    assert read["est_range_scale"] == [None, None, None]
    assert read["calibrate_priors"] == ["", "", ""]
    _as_layout(out, old, [3, 3, 3], set(older_values(2)))  # this layout must have them
    with pytest.raises(DatasetError, match="beacons"):
        read_table(old)
    # one resumed by the version after: its rows of schema 2 and 3 mixed, the table with
    # every column but the priors (schema 4's): each row reads as its scene was solved
    _as_layout(out, old, [2, 3, 3], {"calibrate_priors"})
    assert read_table(old)["calibrate_priors"] == ["", "", ""]
    _as_layout(out, old, [2, 3, 4], {"calibrate_priors"})  # a row of schema 4 must have it
    with pytest.raises(DatasetError, match="calibrate_priors"):
        read_table(old)


def test_a_second_run_on_a_dataset_being_written_is_refused(tmp_path):
    """Two runs on one folder at once (a fresh one and a --resume) both computed the
    same scenes, and the last to end wrote its table and card over the other's."""
    import fcntl

    from mirrorsim.formats.dataset_folder import LOCK_NAME, DatasetError

    out = tmp_path / "ds"
    out.mkdir()
    with open(out / LOCK_NAME, "a") as held:  # the first run, still writing
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(DatasetError, match="another run is writing"):
            run_dataset(1, 5, out, workers=1, spec_path=SPEC, progress=False)
    assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]


def test_the_cards_command_is_the_one_that_made_the_dataset(three_beacons):
    """The card said `mirrorsim dataset --n 2 --seed 5` for a dataset made with a spec
    file, three beacons and self-calibration: rerun, it made another dataset."""
    out, _ = three_beacons
    card = (out / "README.md").read_text()
    assert (f"`mirrorsim dataset --n 2 --seed 5 --out {out} --spec {SPEC} --beacons 3 "
            "--calibrate pan,scale --prior pan=0.3`") in card
    assert "--error-model" not in card  # the shipped model


SPEC_3D = Path(__file__).parent / "data" / "tiny_spec_3d.yaml"


def test_a_3d_spec_draws_the_planar_geometry_then_raises_it(tmp_path):
    """The 3-D keys are drawn after everything else: at 0 they leave every draw as the
    planar spec's, and drawn they raise the objects and lean the glass within their
    ranges."""
    import yaml

    from mirrorsim.pipelines.random_scenes import load_spec, sample_scene

    d = yaml.safe_load(SPEC_3D.read_text())
    d["mirror"]["lean"], d["target"]["z"], d["beacon"]["z"] = 0, 0, 0
    flat = tmp_path / "flat.yaml"
    flat.write_text(yaml.safe_dump(d))
    for k in ("lean",):
        del d["mirror"][k]
    del d["target"]["z"], d["beacon"]["z"]
    planar = tmp_path / "planar.yaml"
    planar.write_text(yaml.safe_dump(d))
    flat_spec, planar_spec, raised = (load_spec(p) for p in (flat, planar, SPEC_3D))
    assert flat_spec.is_3d and raised.is_3d and not planar_spec.is_3d
    for i in range(3):
        a, b = sample_scene(flat_spec, i, "s"), sample_scene(planar_spec, i, "s")
        assert a == b and not a.is_3d
        s = sample_scene(raised, i, "s")
        assert s.is_3d and -3 <= s.mirror.lean <= 3 and 2 <= s.target.z <= 8
        assert all(0 <= b.z <= 8 for b in s.beacons) and len({b.z for b in s.beacons}) == 2


@pytest.mark.parametrize("block, key, value, named", [
    ("target", "z", -1, "target.z"),
    ("beacon", "z", [0, 2, 4], "beacon.z"),
    # a height no scene takes: the draws' refusal names the spec's key beside the scene's
    ("target", "z", 300, "the scene's target.position[2] (the spec's target.z)"),
    ("beacon", "z", 300, "(the spec's beacon.z)"),
    ("beacon", "count", 1, "the scene's beacon.position[2] (the spec's beacon.z)"),
    ("mirror", "lean", [0, 20], "mirror.lean[1]"),
    ("mirror", "lean", "steep", "mirror.lean"),
])
def test_bad_3d_keys_are_refused_with_their_key(tmp_path, capsys, block, key, value, named):
    import yaml

    d = yaml.safe_load(SPEC_3D.read_text())
    d[block][key] = value
    if key == "count":  # one beacon, raised where no scene takes it: its key is beacon.
        d["beacon"]["z"] = 300
    spec = tmp_path / "bad.yaml"
    spec.write_text(yaml.safe_dump(d))
    assert main(["dataset", "--n", "1", "--seed", "0", "--out", str(tmp_path / "o"),
                 "--spec", str(spec), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def raised_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds3d") / "d"
    res = run_dataset(2, 11, out, workers=1, spec_path=SPEC_3D, progress=False)
    return out, res


def test_a_3d_dataset_measures_and_solves_each_scene_in_3d(raised_dataset, capsys):
    from mirrorsim.formats.dataset_folder import read_table
    from mirrorsim.formats.dataset_table import NAMES, SLOT_NAMES

    out, res = raised_dataset
    assert res.failed == 0 and res.rows == 2
    cols = read_table(out)
    assert set(cols) == set(NAMES) | set(SLOT_NAMES[1])
    elevations = []
    for i in range(2):
        scene = load_scene(out / "scenes" / f"scene{i:06d}.yaml")
        assert cols["geometry"][i] == "3d" and scene.is_3d
        assert cols["mirror_lean_deg"][i] == scene.mirror.lean
        assert cols["target_z"][i] == scene.target.z == cols["target_pos_z"][i]
        for k, kind in enumerate(("beacon", "beacon2")):
            assert cols[f"{kind}_pos_z"][i] == scene.beacons[k].z
        for kind in ("target", "beacon", "beacon2"):
            # each image's elevation beside its α and d_total, against an exact reading
            e, e_true = cols[f"{kind}_elevation_meas"][i], cols[f"{kind}_elevation_true"][i]
            assert cols[f"{kind}_elevation_err"][i] == pytest.approx(e - e_true)
            assert abs(e - e_true) < 0.05
            assert 0 < cols[f"{kind}_sigma_elevation_deg"][i] < 0.2
            elevations.append(e_true)
        # the 3-D solution: the target's height, the glass's lean, a 3×3 covariance
        assert abs(cols["est_target_z"][i] - scene.target.z) < 1.0
        assert cols["err_target_height_cm"][i] == pytest.approx(
            cols["est_target_z"][i] - scene.target.z)
        assert abs(cols["est_mirror_lean_deg"][i] - scene.mirror.lean) < 1.0
        assert cols["target_cov_zz"][i] > 0 and cols["planar_err_target_cm"][i] is not None
        # the measurements the solve saw: 3-D, each with its elevation
        m = json.loads((out / "frames" / f"scene{i:06d}" /
                        f"scene{i:06d}.measurements.json").read_text())
        assert all("elevation_deg" in b for b in m["beacons"]) and len(m["beacons"]) == 2
    assert max(map(abs, elevations)) > 0.5  # (raised up to 8 cm: not all at the lens's height)
    # the card says what errormodel takes; the frames' lines carry the table's exact values
    assert "fits a 3-D error model" in (out / "README.md").read_text()
    lines = [json.loads(x) for x in (out / "metadata.jsonl").read_text().splitlines()]
    for line in lines:
        i = line["index"]
        assert (line["target_alpha_true"], line["target_d_true"]) == (
            cols["target_alpha_true"][i], cols["target_d_true"][i])
    # a model's validation solves planar rows again: these are refused in one line,
    # before a model is fitted and written
    model = out.parent / "m.json"
    assert main(["errormodel", str(out), "--test", str(out), "--out", str(model)]) == 2
    err = capsys.readouterr().err
    assert "solved in 3-D" in err and len(err.strip().splitlines()) == 1
    assert not model.exists() and not model.with_suffix(".png").exists()


def test_a_planar_dataset_has_no_3d_values(one_worker):
    from mirrorsim.formats.dataset_folder import read_table

    cols = read_table(one_worker[0])
    assert cols["geometry"] == ["planar"] * 3 and cols["target_z"] == [0.0] * 3
    assert cols["beacon_pos_z"] == [0.0] * 3
    assert cols["target_elevation_meas"] == [None] * 3 and cols["est_target_z"] == [None] * 3


def test_a_3d_dataset_takes_the_3d_calibration(tmp_path, capsys):
    """A 3-D spec's scenes take the pitch and the beacons' position σ; a planar spec's
    refuse the pitch in one line, before anything is written."""
    out = tmp_path / "o"
    assert main(["dataset", "--n", "1", "--seed", "0", "--out", str(out), "--spec",
                 str(SPEC), "--calibrate", "pitch", "--quiet"]) == 2
    assert "pitch" in capsys.readouterr().err and not out.exists()
    from mirrorsim.pipelines.dataset import _run_spec

    spec = _run_spec(SPEC_3D, sampler=None, beacons=None,
                     calibration=SelfCalibration(("pan", "pitch"), 0.1))
    assert spec.is_3d


def test_a_table_of_several_beacons_before_3d_is_read(three_beacons, tmp_path):
    """A dataset of three beacons made before the 3-D columns (schema 5, its rows and
    table without them): each beacon's 3-D columns read as a planar scene's."""
    from mirrorsim.formats.dataset_folder import read_table
    from mirrorsim.formats.dataset_table import older_values

    out, _ = three_beacons
    old = tmp_path / "old"
    dropped = set(older_values(5, 3))
    assert {"beacon2_pos_z", "beacon3_elevation_err", "target_pos_z"} <= dropped
    _as_layout(out, old, [5, 5], dropped)
    read = read_table(old)
    assert read["geometry"] == ["planar"] * 2
    assert read["beacon3_pos_z"] == [0.0, 0.0] and read["beacon2_elevation_err"] == [None] * 2


def test_error_model_fits_a_3d_dataset_s_elevation(tmp_path):
    """Synthetic 3-D rows, each image's elevation error ~ N(0, σ_ε) (target 0.01°, beacon
    0.004°): the model fits an elevation law per kind to that σ, writes and reads it
    back, and gives each image its elevation σ as a Gaussian's; its tail is not fitted
    (the validation solves planar rows).  Rows of both geometries, or a file with one
    kind's elevation law alone, are refused."""
    from mirrorsim.formats.error_model import ImageFeatures
    from mirrorsim.formats.error_model_file import load_error_model, model_from_dict

    n = 600
    rng = np.random.default_rng(4)
    extra = {"geometry": ["3d"] * n}
    for kind, s in (("target", 0.01), ("beacon", 0.004)):
        extra[f"{kind}_elevation_err"] = rng.normal(0, s, n)
    cols = synthetic_columns(n, 3, **extra)
    model = errormodel.fit(cols)
    assert model.three_d and model.ellipsoid_scale == 1.0 and model.tail.gaussian
    for kind, s in (("target", 0.01), ("beacon", 0.004)):
        assert model.fits[kind]["elevation"].typical_sigma == pytest.approx(s, rel=0.1)
    # its ellipsoid's scale: the 95th percentile of its rows' distances over χ₃'s radius
    import mirrorsim.pipelines.validate3d as v3
    from mirrorsim.pipelines.evaluate3d import CHI2_3_R95

    d = np.linspace(0.0, 2 * CHI2_3_R95, 201)  # its 95th percentile: 1.9 radii
    real, v3.distances3 = v3.distances3, lambda *_: d
    try:
        model = errormodel.with_its_ellipsoid(model, tmp_path, cols)
    finally:
        v3.distances3 = real
    assert model.ellipsoid_scale == pytest.approx(1.9)
    path = tmp_path / "m3.json"
    errormodel.write_model(model, path)
    back = load_error_model(path)
    assert back.three_d and back.fits == model.fits
    assert back.ellipsoid_scale == model.ellipsoid_scale
    im = ImageFeatures(0.0, 50.0, 200.0, 0.5, 0.01)
    t, b = back.gaussian_elevations((im, im), 0.0, fx_px=1500.0)
    assert t / b == pytest.approx(2.5, rel=0.25) and 0.005 < t < 0.03
    assert errormodel.fit(synthetic_columns(n, 3)).gaussian_elevations((im,), 0.0) is None
    with pytest.raises(ValueError, match="mix planar and 3-D"):
        errormodel.fit({**cols, "geometry": ["3d"] * (n - 1) + ["planar"]})
    doc = json.loads(path.read_text())
    del doc["sha256"]
    with pytest.raises(Exception, match="ellipsoid_scale: .*missing"):  # (not 1 by default)
        model_from_dict({k: v for k, v in doc.items() if k != "ellipsoid_scale"}, "e.json")
    del doc["objects"]["beacon"]["elevation"]
    with pytest.raises(Exception, match="objects.beacon.elevation: missing"):
        model_from_dict(doc, "edited.json")
    # a planar model writes what it wrote before (its digest: a dataset resumes with it),
    # and refuses a 3-D model's scale
    planar = errormodel.fit(synthetic_columns(n, 3)).to_json()
    assert "ellipsoid_scale" not in planar and set(planar["units"]) == {"alpha", "d_rel"}
    with pytest.raises(Exception, match="ellipsoid_scale"):
        model_from_dict({**planar, "ellipsoid_scale": 1.5}, "edited.json")


def test_a_3d_dataset_s_rows_solved_again_are_its_own(raised_dataset):
    """Each 3-D row solved again from its measurements file and its columns, with the
    model that made it (the shipped ideal one): the truth's distance is the row's own,
    to 1e-6 (the features, σ's, calibration and solve are evaluate's)."""
    from mirrorsim.formats.dataset_folder import read_table
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines.validate3d import distances3

    out, _ = raised_dataset
    cols = read_table(out)
    assert distances3(default_error_model(), out, cols) == pytest.approx(
        cols["target_mahalanobis"], rel=1e-6)
