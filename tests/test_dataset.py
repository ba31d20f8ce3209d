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

from mirrorsim import errormodel
from mirrorsim.cli import main
from mirrorsim.dataset import collect_rows, run_dataset
from mirrorsim.scenefile import load_scene

SPEC = Path(__file__).parent / "data" / "tiny_spec.yaml"
VOLATILE = ("seconds_total", "seconds_sample", "traceback")


def _stable(rows):
    """Rows without their timings; every row must be a success (identical failures
    would otherwise compare equal)."""
    assert rows and all(r["error"] == "" for r in rows), [r.get("error") for r in rows]
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds") / "a"
    res = run_dataset(3, 3, out, workers=1, spec_path=SPEC, progress=False)
    return out, res


def test_tiny_dataset_end_to_end(one_worker):
    out, res = one_worker
    assert res["rows"] == 3 and res["computed"] == 3 and res["failed"] == 0
    import pyarrow.parquet as pq

    table = pq.read_table(out / "dataset.parquet").to_pydict()
    assert table["index"] == [0, 1, 2]
    assert table["error"] == ["", "", ""]
    for col in ("target_alpha_err", "beacon_d_rel_err", "err_target_cm", "variant", "spp",
                "mirror_yaw_deg", "target_incidence_deg"):
        assert col in table
    assert "dataset.parquet" in (out / "README.md").read_text()
    # by default a frame's PNG, truth and capture record only (no ids, no annotated)
    assert sorted(f.name for f in (out / "frames" / "scene000000").iterdir()) == [
        "scene000000.capture.json", "scene000000.json", "scene000000.png"]
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


def test_error_model_recovers_a_known_law():
    """Synthetic rows with α error ~ N(0.001 + 2e-5·d, 0.002 + 3e-5·d) and d error ~
    N(−0.001, 0.003 + 0.5/height_px): the fit finds those coefficients."""
    rng = np.random.default_rng(0)
    n = 4000
    cols = {"index": list(range(n)), "error": [""] * n}
    for kind in ("target", "beacon"):
        d = rng.uniform(40, 140, n)
        h = rng.uniform(40, 300, n)
        cols[f"{kind}_d_true"] = d
        cols[f"{kind}_off_axis_deg"] = rng.uniform(-20, 20, n)
        cols[f"{kind}_incidence_deg"] = rng.uniform(0, 60, n)
        cols[f"{kind}_height_px_true"] = h
        cols[f"{kind}_alpha_err"] = rng.normal(0.001 + 2e-5 * d, 0.002 + 3e-5 * d)
        cols[f"{kind}_d_rel_err"] = rng.normal(-0.001, 0.003 + 0.5 / h)
    model = errormodel.fit(cols)
    a = model["objects"]["target"]["alpha"]
    assert a["bias"][1] == pytest.approx(2e-5, abs=4e-6)
    assert a["spread"][1] == pytest.approx(3e-5, abs=8e-6)
    r = model["objects"]["beacon"]["d_rel"]
    assert r["bias"][0] == pytest.approx(-0.001, abs=4e-4)
    assert r["spread"][4] == pytest.approx(0.5, rel=0.15)
    # the solver's σ pair comes out of the model
    assert 0.002 < model["sigma"]["alpha_deg"] < 0.01


def test_error_model_fits_a_signed_off_axis_bias_through_outliers():
    """α bias = 0.003°·(off-axis/10°) changes sign across the axis; σ = 0.002°; 3 % of the
    rows are gross errors of ±0.5°.  The signed, robust fit recovers the slope and a σ
    near 0.002° (a least-squares fit on |off-axis| can do neither: its σ would be
    ≈ 0.087° from the outliers alone)."""
    rng = np.random.default_rng(1)
    n = 3000
    cols = {"index": list(range(n)), "error": [""] * n}
    for kind in ("target", "beacon"):
        off = rng.uniform(-25, 25, n)
        cols[f"{kind}_d_true"] = rng.uniform(40, 140, n)
        cols[f"{kind}_off_axis_deg"] = off
        cols[f"{kind}_incidence_deg"] = rng.uniform(0, 60, n)
        cols[f"{kind}_height_px_true"] = rng.uniform(40, 300, n)
        err = 0.0003 * off + rng.normal(0, 0.002, n)
        gross = rng.random(n) < 0.03
        err[gross] += rng.choice([-0.5, 0.5], gross.sum())
        cols[f"{kind}_alpha_err"] = err
        cols[f"{kind}_d_rel_err"] = rng.normal(0, 0.001, n)
    model = errormodel.fit(cols)
    a = model["objects"]["target"]["alpha"]
    assert errormodel.FEATURES[2] == "off_axis_deg"
    assert a["bias"][2] == pytest.approx(0.0003, rel=0.05)
    middle = np.array([[1.0, 90.0, 0.0, 30.0, 1 / 170]])
    bias, sd = errormodel.predict(model, "target", "alpha", middle)
    assert abs(bias[0]) < 0.0005 and sd[0] == pytest.approx(0.002, rel=0.3)


def test_errormodel_command_on_a_dataset(one_worker, tmp_path, capsys):
    out, _ = one_worker
    # three rows are too few for five coefficients: a clear refusal
    assert main(["errormodel", str(out)]) == 2
    assert "too few" in capsys.readouterr().err
    # a model file feeds solve/montecarlo/plan
    rng = np.random.default_rng(1)
    n = 50
    cols = {"index": list(range(n)), "error": [""] * n}
    for kind in ("target", "beacon"):
        cols.update({f"{kind}_d_true": rng.uniform(40, 140, n),
                     f"{kind}_off_axis_deg": rng.uniform(-20, 20, n),
                     f"{kind}_incidence_deg": rng.uniform(0, 60, n),
                     f"{kind}_height_px_true": rng.uniform(40, 300, n),
                     f"{kind}_alpha_err": rng.normal(0, 0.004, n),
                     f"{kind}_d_rel_err": rng.normal(0, 0.005, n)})
    model_path = tmp_path / "m.json"
    errormodel.write_model(errormodel.fit(cols), model_path)
    assert main(["montecarlo", "--error-model", str(model_path)]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 6  # a 4th row
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

    from mirrorsim.calibrate import _cache_file, calibration_key
    from mirrorsim.sampler import camera_models, load_spec

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
    cache = json.loads(_cache_file().read_text())
    assert all(k in cache for k in keys)
    run_dataset(3, 1, tmp_path / "d", workers=1, spec_path=path, progress=False)
    for i in range(3):
        cam = load_scene(tmp_path / "d" / "scenes" / f"scene{i:06d}.yaml").camera
        assert (cam.height, cam.hfov) in {(5.5, 65.2), (7.5, 62.0)}
