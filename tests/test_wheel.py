"""The wheel a user can pip install: it carries the bundled scenes, the dataset specs,
the shipped error models and the template, and runs away from the clone."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CARRIED = ("mirrorsim/data/template.yaml", "mirrorsim/data/error_model.json",
           "mirrorsim/data/error_model_bench.json",
           *(f"mirrorsim/data/scenes/{n}.yaml" for n in (
               "default", "exp1", "exp2", "exp3", "dataset_spec", "dataset_spec_bench",
               "dataset_spec_domain", "dataset_spec_domain_bench")),
           "mirrorsim/data/scenes/bench/exp1_3beacons.yaml")


@pytest.mark.slow
def test_a_wheel_installs_in_a_fresh_venv_and_runs_new_check_and_evaluate(tmp_path):
    """``python -m build`` makes the wheel; a fresh venv away from the clone installs it
    (its dependencies taken from this environment's site-packages, which a ``.pth``
    adds, so that the test downloads nothing) and runs ``new``, ``check`` and
    ``evaluate`` there."""
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir", str(dist),
                    str(ROOT)], check=True, capture_output=True)
    wheel = next(dist.glob("mirrorsim-*.whl"))
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    assert not [n for n in CARRIED if n not in names]
    assert not [n for n in names if n.startswith(("tests/", "benchmarks/", "docs/"))]

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    site = next((venv / "lib").glob("python3*/site-packages"))
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    bin_ = venv / "bin"
    # this environment's own: a PYTHONPATH holding a clone's mirrorsim made pip take the
    # wheel as installed already
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{bin_}:{env['PATH']}"
    subprocess.run([bin_ / "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
                   check=True, capture_output=True, env=env)
    work = tmp_path / "work"  # away from the clone: no scenes/, no mirrorsim/ beside it
    work.mkdir()

    def run(*argv: str) -> str:
        done = subprocess.run([str(bin_ / "mirrorsim"), *argv], cwd=work, env=env,
                              capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, (argv, done.stderr[-600:])
        return done.stdout

    where = subprocess.run([str(bin_ / "python"), "-c",
                            "import mirrorsim; print(mirrorsim.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True).stdout
    assert where.startswith(str(site)), where  # the wheel's, not the clone's
    run("new", "mine.yaml")
    run("new", "paper.yaml", "--like", "exp1")
    assert "valid" in run("check", "mine.yaml") and "valid" in run("check", "paper.yaml")
    out = run("evaluate", "paper.yaml", "--out", "out", "--spp", "4", "--quiet")
    assert "target" in out and (work / "out" / "paper.report.json").is_file()
