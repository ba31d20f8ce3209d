"""Re-run every command whose output is a table or figure in the README or the docs,
and write what it printed into docs/results/, stamped with the command, the commit, the
date and the machine.

    python docs/regenerate.py                # all of them (about an hour on 2 cores)
    python docs/regenerate.py demo budget_exp1   # some
    python docs/regenerate.py --list

The docs' pages include docs/results/<name>.md (``--8<--``); the README's quick-start
block is the ``demo`` result, copied between its markers.  ``make docs`` runs this, then
``docs/gen_reference.py`` and ``docs/make_images.py``.  ``tests/test_docs.py`` holds
every included result to this registry and the README's block to ``demo``'s.

Throughput results time the machine: run them on a quiet one.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "results"
sys.path.insert(0, str(ROOT / "benchmarks"))

from stamp import stamp  # noqa: E402

MS = "mirrorsim"
PY = "python"


@dataclass(frozen=True)
class Result:
    """A result: what makes it (run in the repository root, in order; the last command's
    stdout is the result), and whether that output is Markdown or plain text."""

    name: str
    commands: tuple[str, ...]
    markdown: bool = False
    about: str = ""
    fresh: tuple[str, ...] = ()  # output folders removed first (what a fresh clone has)


RESULTS: tuple[Result, ...] = (
    Result("demo", (f"{MS} evaluate scenes/default.yaml --keep plot annotated",),
           about="make demo: the default scene end to end", fresh=("renders/default",)),
    Result("budget_exp1", (f"{MS} budget scenes/bench/exp1.yaml",),
           about="the paper's EXP1 on a hand-built bench: the error budget",
           fresh=("renders/exp1_bench",)),
    Result("budget_raised", (f"{MS} budget scenes/bench/raised.yaml",),
           about="the 3-D scene on EXP1's hand-built bench: the error budget in 3-D",
           fresh=("renders/raised_bench",)),
    Result("plan_raised", (f"{MS} plan scenes/raised.yaml",),
           about="the 3-D scene's beacon placement, each position's post by the 3-D bound"),
    Result("evaluate_exp1_board",
           (f"{MS} evaluate scenes/bench/exp1_3beacons.yaml --calibrate pan,scale "
            "--beacon-sigma 0.115 --board-pose --out renders/exp1_board --quiet",),
           about="EXP1's bench with three planned beacons, self-calibrated with the "
                 "camera's pose from the pegboard",
           fresh=("renders/exp1_board",)),
    Result("budget_exp1_3beacons",
           (f"{MS} budget scenes/bench/exp1_3beacons.yaml --calibrate pan,scale "
            "--beacon-sigma 0.115",),
           about="EXP1's bench with three planned beacons, plain and self-calibrated",
           fresh=("renders/exp1_bench_3beacons",)),
    Result("detect_accuracy",
           (f"{PY} benchmarks/detect.py --spec scenes/dataset_spec.yaml --frames 40 "
            "--seed 4320",), markdown=True,
           about="the detector against the truth on 40 random scenes"),
    Result("detect_offaxis",
           (f"{PY} benchmarks/detect.py --offaxis --plot docs/detect_offaxis.png",),
           markdown=True, about="the detector against the off-axis angle"),
    Result("edges", (f"{PY} benchmarks/edges.py --spp 576",), markdown=True,
           about="each edge against its exact projection, default scene, 576 spp"),
    Result("pencil_edges", (f"{PY} benchmarks/pencil_edges.py --spp 1024",), markdown=True,
           about="the pencil's top and foot against the truth, 12 scenes"),
    Result("plan_exp3", (f"{MS} plan scenes/exp3.yaml --out docs/plan_exp3.png",),
           about="the placement analysis of EXP3 (and its figure)"),
    Result("montecarlo3d",
           (f"{MS} montecarlo --iterations 2000 --lean 2 --target-z 0.5 --camera-height 0.3 "
            "--sigma 0.02 0.2 --sigma 0.1 0.5 --sigma 0.5 1 --sigma 1.73 3.2",),
           about="the Table 1 protocol with a leaning mirror and a raised target: the 3-D "
                 "closed form beside the planar one on the same draws"),
    Result("montecarlo", (f"{MS} montecarlo --iterations 2000",),
           about="the paper's Table 1 protocol"),
    Result("paper", (f"{PY} benchmarks/paper.py",), markdown=True,
           about="the paper's experiments side by side", fresh=("renders/paper",)),
    Result("paper_3beacons", (f"{PY} benchmarks/paper.py --beacons 3",), markdown=True,
           about="the paper's benches with three planned beacons, plain and self-calibrated",
           fresh=("renders/paper/bench1", "renders/paper/bench3")),
    Result("calibrate_default", (f"{MS} calibrate scenes/default.yaml",),
           about="the default camera's size-constancy calibration"),
    Result("sensor_noise", (f"{PY} benchmarks/sensor_noise.py",),
           about="sensor noise's shift of the target's measurements against first order"),
    Result("lean_geometry", (f"{PY} benchmarks/lean_geometry.py --scenes 400",),
           markdown=True, about="3-D SLTR against the planar solver on leaning mirrors: "
                                "the geometry alone"),
    Result("evaluate3d", (f"{PY} benchmarks/evaluate3d.py --scenes 60 --seed 61206302",),
           markdown=True, about="3-D scenes rendered end to end: the 3-D solve beside the "
                                "planar solve on the same frames",
           fresh=("renders/evaluate3d-61206302",)),
    Result("evaluate3d_wide",
           (f"{PY} benchmarks/evaluate3d.py --scenes 40 --seed 61206303 --wide",),
           markdown=True, about="3-D scenes drawn wider than the σ factors' development "
                                "scenes: the acceptance set",
           fresh=("renders/evaluate3d-wide-61206303",)),
    Result("dataset3d",
           (f"{MS} dataset --spec scenes/dataset_spec_3d.yaml --n 40 --seed 61207001 "
            "--out renders/dataset3d --quiet",
            f"{PY} benchmarks/evaluate3d.py --dataset renders/dataset3d"),
           markdown=True, about="a 3-D dataset of the bundled 3-D spec (a third generator, "
                                "fitted on nothing): the 3-D solve beside the planar one",
           fresh=("renders/dataset3d",)),
    Result("error_model_3d",
           (f"{MS} dataset --spec scenes/dataset_spec_3d.yaml --n 200 --seed 7101 "
            "--out renders/em-3d --workers 2 --quiet",
            f"{MS} errormodel renders/em-3d",
            f"{PY} benchmarks/evaluate3d.py --scenes 60 --seed 61206302 "
            "--error-model renders/em-3d/error_model.json",
            f"{PY} benchmarks/evaluate3d.py --scenes 40 --seed 61206303 --wide "
            "--error-model renders/em-3d/error_model.json",
            f"{MS} dataset --spec scenes/dataset_spec_3d.yaml --n 40 --seed 61207001 "
            "--out renders/dataset3d-em3d --error-model renders/em-3d/error_model.json "
            "--quiet",
            f"{PY} benchmarks/evaluate3d.py --acceptance renders/evaluate3d-61206302 "
            "renders/evaluate3d-wide-61206303 renders/dataset3d-em3d "
            "--error-model renders/em-3d/error_model.json"),
           markdown=True, about="a 3-D error model fitted on 200 scenes of the 3-D spec, "
                                "on the three 3-D acceptance sets",
           fresh=("renders/em-3d", "renders/dataset3d-em3d",
                  "renders/evaluate3d-61206302/rows-error_model",
                  "renders/evaluate3d-wide-61206303/rows-error_model")),
    Result("evaluate3d_factors",
           (f"{PY} benchmarks/evaluate3d.py --scenes 35 --seed 7001",
            f"{PY} benchmarks/evaluate3d.py --scenes 35 --seed 7002",
            f"{PY} benchmarks/evaluate3d.py --scenes 30 --seed 7003 --wide",
            f"{PY} benchmarks/evaluate3d.py --scenes 30 --seed 7004 --wide",
            f"{PY} benchmarks/evaluate3d.py --residuals renders/evaluate3d-7001 "
            "renders/evaluate3d-7002 renders/evaluate3d-wide-7003 renders/evaluate3d-wide-7004"),
           markdown=True, about="the 3-D σ factors' development scenes: each reading's "
                                "errors in the planar model's σ's, and the factor they call for",
           fresh=("renders/evaluate3d-7001", "renders/evaluate3d-7002",
                  "renders/evaluate3d-wide-7003", "renders/evaluate3d-wide-7004")),
    Result("evaluate_raised",
           (f"{MS} evaluate scenes/bench/raised.yaml --out renders/raised_plain --quiet",),
           about="the 3-D scene on EXP1's hand-built bench, evaluated as it stands",
           fresh=("renders/raised_plain",)),
    Result("evaluate_raised_board",
           (f"{MS} evaluate scenes/bench/raised.yaml --board-pose --out renders/raised_board "
            "--quiet",),
           about="the 3-D scene on EXP1's hand-built bench, every image read through the "
                 "camera's pose the board gives", fresh=("renders/raised_board",)),
    Result("reflector_size", (f"{PY} benchmarks/reflector_size.py",), markdown=True,
           about="the paper's open question: the target's error as the reflector shrinks"),
    Result("crlb", (f"{PY} benchmarks/uncertainty.py --scenes 40 --draws 1000",),
           markdown=True, about="estimator efficiency against the Cramér–Rao bound"),
    Result("default_ellipse", (f"{PY} benchmarks/uncertainty.py --renders 20",),
           markdown=True, about="the default scene's own ellipse over fresh renders"),
    Result("heldout_ideal",
           (f"{MS} dataset --n 200 --seed 734211 --out renders/ideal_test --workers 2 "
            "--quiet",
            f"{MS} errormodel --test renders/ideal_test --plot docs/reliability_ideal.png"),
           about="the shipped error model on 200 held-out scenes of the ideal bench",
           fresh=("renders/ideal_test",)),
    Result("heldout_bench",
           (f"{MS} dataset --n 100 --seed 515151 --spec scenes/dataset_spec_bench.yaml "
            "--out renders/bench_train --workers 2 --quiet",
            f"{MS} dataset --n 100 --seed 818181 --spec scenes/dataset_spec_bench.yaml "
            "--out renders/bench_test --workers 2 --quiet",
            f"{MS} errormodel renders/bench_train --test renders/bench_test "
            "--plot docs/reliability_bench.png"),
           about="a bench-fitted error model on 100 held-out bench scenes",
           fresh=("renders/bench_train", "renders/bench_test")),
    Result("heldout_bench_3beacons",
           (f"{MS} dataset --n 100 --seed 515151 --spec scenes/dataset_spec_bench.yaml "
            "--out renders/bench_train3 --workers 2 --quiet",
            f"{MS} dataset --n 60 --seed 929292 --spec scenes/dataset_spec_bench.yaml "
            "--beacons 3 --calibrate pan,scale --beacon-sigma 0.115 "
            "--out renders/bench3_test --workers 2 --quiet",
            f"{MS} errormodel renders/bench_train3 --test renders/bench3_test"),
           about="the bench-fitted model on 60 held-out benches of three random beacons, "
                 "self-calibrated (about 12 min)",
           fresh=("renders/bench_train3", "renders/bench3_test")),
    Result("acceptance",
           (f"{PY} benchmarks/acceptance.py --scenes 100 --seed 61207081",
            f"{PY} benchmarks/acceptance.py --scenes 100 --seed 61207082 --bench",
            f"{PY} benchmarks/acceptance.py --report renders/acceptance-61207081-ideal "
            "renders/acceptance-61207082-bench"),
           markdown=True,
           about="the error bars on 200 scenes of the acceptance generator's own, ideal "
                 "and bench, with the default model choice (about 45 min)",
           fresh=("renders/acceptance-61207081-ideal", "renders/acceptance-61207082-bench")),
    Result("acceptance_selfcal",
           (f"{PY} benchmarks/acceptance.py --scenes 40 --seed 61207083 --bench --beacons 3",),
           markdown=True,
           about="self-calibration on 40 independent three-beacon benches against plain "
                 "least squares (about 15 min)",
           fresh=("renders/acceptance-61207083-bench",)),
    Result("particle", (f"{PY} benchmarks/particle.py",), markdown=True,
           about="the particle filter against the batch smoother, synthetic"),
    Result("track_paths", (f"{PY} benchmarks/track.py",), markdown=True,
           about="the moving beacon's paths on rendered frames (about 20 min)",
           fresh=("renders/bench_track",)),
    Result("particle_nees",
           (f"{PY} benchmarks/particle.py --nees --seeds 20 --particles 2000",),
           markdown=True, about="the particle filter's consistency on synthetic measurements"),
    Result("track_coverage", (f"{PY} benchmarks/track.py --coverage 3 --steps 8",),
           markdown=True, about="the particle filter's 95 % region on rendered frames"),
    Result("track_fixed", (f"{PY} benchmarks/track.py --beside --steps 10 --seed 8649690",),
           markdown=True, about="the moving beacon alone and beside a fixed beacon, on "
                                "rendered frames (the seed the page reads)"),
    Result("selfcal_bench",
           (f"{PY} benchmarks/selfcal.py --scenes 40 --seed 4417001 --priors",),
           markdown=True, about="self-calibration on 40 rendered bench scenes with three "
                                "planned beacons, without and with priors (about 8 min)"),
    Result("selfcal_bench_fresh",
           (f"{PY} benchmarks/selfcal.py --scenes 40 --seed 15482401 --priors",),
           markdown=True, about="self-calibration on 40 benches of the seed drawn afresh "
                                "for it on 2026-12-03, without and with priors (about 8 "
                                "min)"),
    Result("selfcal_bench_priors",
           (f"{PY} benchmarks/selfcal.py --scenes 40 --priors --seed 3248510",),
           markdown=True, about="self-calibration with and without priors from the spec's "
                                "ranges, on 40 benches of the seed the page reads, drawn "
                                "afresh for it (about 8 min)"),
    Result("selfcal_bench_board",
           (f"{PY} benchmarks/selfcal.py --scenes 40 --priors --seed 13179213",),
           markdown=True, about="self-calibration with the board's camera pose, on 40 "
                                "benches of a seed drawn afresh for it on 2026-12-03 after "
                                "the board's columns were measured on the three above "
                                "(about 10 min)"),
    Result("selfcal_pooled", (f"{PY} benchmarks/selfcal_pooled.py",), markdown=True,
           about="the four JPEG runs above, their ratios pooled with bootstrap intervals "
                 "(after them: it reads their tables)"),
    Result("selfcal_bench_png",
           (f"{PY} benchmarks/selfcal.py --scenes 40 --seed 4417001 --lossless",),
           markdown=True, about="the same 40 benches with their frames stored as PNG"),
    Result("jpeg_edges", (f"{PY} benchmarks/jpeg_edges.py --scenes 12",), markdown=True,
           about="what JPEG does to each measured edge, against the exact projections"),
    Result("jpeg_reference", (f"{PY} benchmarks/jpeg_reference.py",), markdown=True,
           about="the calibration's references recorded as JPEG"),
    Result("throughput_commands", (f"{PY} benchmarks/commands.py --repeat 3",),
           markdown=True, about="whole commands as a user waits for them (quiet machine)"),
    Result("render_variants", (f"{PY} benchmarks/render.py --repeat 2",), markdown=True,
           about="a full-size render per Mitsuba variant (quiet machine)"),
    Result("throughput_dataset", (f"{PY} benchmarks/dataset.py --n 24 --workers 2",),
           markdown=True, about="a new dataset's frames a minute (quiet machine)"),
    Result("throughput_freeze", (f"{PY} benchmarks/freeze.py --frames 6 --fresh 4",),
           markdown=True, about="what replaying recorded kernels saves a frame, warm and "
                                "in a fresh process; the cached code fingerprint"),
    Result("throughput_ratio",
           (f"{PY} benchmarks/pieces.py --scenes 6 --rss 48 --ratio 10",), markdown=True,
           about="a frame's pieces, a worker's memory over 48 scenes, and a frame's wall "
                 "time against the bare render"),
)
BY_NAME = {r.name: r for r in RESULTS}
HEADER = "<!-- generated by `python docs/regenerate.py {name}`: do not edit -->\n"
README_BEGIN, README_END = "<!-- begin demo -->", "<!-- end demo -->"


def render_result(r: Result, stdout: str, stamped: str) -> str:
    """The result file's text: a header, the commands and stamp, and what they printed."""
    cmds = " && ".join(f"`{c}`" for c in r.commands)
    stdout = stdout.replace(f"{ROOT}/", "")  # paths as the repository names them
    stdout = re.sub(r"\x1b\[[0-9;]*m", "", stdout)  # a terminal's colours
    # Mitsuba's own log lines ("2026-12-02 ... WARN ...") are not the result
    stdout = "\n".join(ln for ln in stdout.split("\n")
                       if not re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d", ln))
    body = stdout.rstrip() + "\n" if r.markdown else f"```text\n{stdout.rstrip()}\n```\n"
    return f"{HEADER.format(name=r.name)}\n*{cmds} · {stamped}*\n\n{body}"


def run(r: Result) -> str:
    """Run a result's commands; the last one's stdout."""
    env = {**os.environ, "PATH": f"{ROOT / '.venv' / 'bin'}{os.pathsep}{os.environ['PATH']}"}
    for folder in r.fresh:
        shutil.rmtree(ROOT / folder, ignore_errors=True)
    out = ""
    for c in r.commands:
        print(f"$ {c}", file=sys.stderr, flush=True)
        p = subprocess.run(shlex.split(c), cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
        if p.returncode != 0:
            raise SystemExit(f"{r.name}: `{c}` exited with {p.returncode}")
        out = p.stdout
    return out


def demo_block(result_text: str) -> str:
    """The README's quick-start block from the demo result: its stamp and its table."""
    lines = result_text.split("\n")[2:]  # without the header comment and blank line
    return "\n".join(lines).rstrip() + "\n"


def write_readme_demo(result_text: str) -> None:
    """Copy the demo result into the README between its markers."""
    readme = ROOT / "README.md"
    s = readme.read_text(encoding="utf-8")
    new = f"{README_BEGIN}\n{demo_block(result_text)}{README_END}"
    s2 = re.sub(re.escape(README_BEGIN) + r".*?" + re.escape(README_END), lambda _m: new, s,
                flags=re.S)
    readme.write_text(s2, encoding="utf-8")


def main() -> int:
    """Make the results named (all by default)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="results to make (default: all)")
    ap.add_argument("--list", action="store_true", help="list the results and exit")
    a = ap.parse_args()
    if a.list:
        for r in RESULTS:
            print(f"{r.name:22s} {r.about}")
        return 0
    unknown = [n for n in a.names if n not in BY_NAME]
    if unknown:
        print(f"unknown result(s) {', '.join(unknown)}: see --list", file=sys.stderr)
        return 2
    OUT.mkdir(parents=True, exist_ok=True)
    for name in a.names or BY_NAME:
        r = BY_NAME[name]
        t0 = time.perf_counter()
        stamped = stamp()  # the code the run starts from (a commit during it is not it)
        text = render_result(r, run(r), stamped)
        tmp = OUT / f".{name}.md.tmp"
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(OUT / f"{name}.md")
        if name == "demo":
            write_readme_demo(text)
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
