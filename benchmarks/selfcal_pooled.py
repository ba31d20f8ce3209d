"""The self-calibration benchmark's ratios pooled over its registered runs, with how far
40 scenes let them move.

    python benchmarks/selfcal_pooled.py [TABLE ...] [--draws 4000] [--seed 0]

Reads the per-scene tables that ``benchmarks/selfcal.py`` printed (by default the JPEG
runs registered in ``docs/results/``: four seeds of 40 benches each), and prints for
each run and for all of them pooled the ratios of medians the issue's targets are stated
in (self-calibrated / plain, with the believed and with the exact positions; the same
self-calibrated with priors, and with the board's camera pose, where every run pooled
has them; the reference / plain), each with a 90 % bootstrap interval: the scenes
redrawn with replacement within each run, ``--draws`` times. A ratio of medians over 40
scenes moves a lot with the scenes drawn; the interval says how much, so that a target
met or missed on one run is not taken for more than it is. The tables' values are
printed to three decimals, so a run's ratio here may differ in its last digit from the
one printed under its table.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np
from clone import ROOT  # noqa: E402  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

RUNS = ("selfcal_bench", "selfcal_bench_fresh", "selfcal_bench_priors", "selfcal_bench_board")
# the per-scene table's columns read here, by their headings as selfcal.py prints them
HEADINGS = {"plain": "plain (cm)", "selfcal": "self-calibrated",
            "plain_exact": "plain, exact positions",
            "selfcal_exact": "self-calibrated, exact positions",
            "reference": "reference: pan and scale known",
            # a run with --priors has these two more (NaN where a run has not)
            "priors": "self-calibrated with priors", "priors_exact": "… exact positions",
            # the camera's pose from the board's holes (evaluate --board-pose)
            "board": "board's pose, self-calibrated",
            "board_exact": "board's pose, exact positions"}
COLUMNS = list(HEADINGS)
OPTIONAL = ("priors", "priors_exact", "board", "board_exact")
# the run whose benches chose the JPEG foot's 5-px window (docs/results.md)
TUNED = "selfcal_bench"
RATIOS = (("self-calibrated / plain, believed positions", "selfcal", "plain"),
          ("self-calibrated / plain, exact positions", "selfcal_exact", "plain_exact"),
          ("with priors / plain, believed positions", "priors", "plain"),
          ("with priors / plain, exact positions", "priors_exact", "plain_exact"),
          ("board's pose / plain, believed positions", "board", "plain"),
          ("board's pose / plain, exact positions", "board_exact", "plain_exact"),
          ("reference / plain, exact positions", "reference", "plain_exact"))


def read_run(path: Path) -> tuple[str, np.ndarray]:
    """The run's seed (as its header says) and its per-scene columns (scenes × COLUMNS),
    each found by its heading (an OPTIONAL one a run lacks: NaN)."""
    text = path.read_text(encoding="utf-8")
    if "frames stored as PNG" in text:
        sys.exit(f"{path}: a run of lossless frames; these ratios are the JPEG benches'")
    found = re.search(r"\bseed (\d+)", text)
    lines = text.splitlines()
    head = next((line for line in lines if line.startswith("| scene |")), None)
    if head is None:
        sys.exit(f"{path}: no table headed | scene | … to read")
    names = [c.strip() for c in head.split("|")[1:-1]]
    missing = [h for k, h in HEADINGS.items() if h not in names and k not in OPTIONAL]
    if missing:
        sys.exit(f"{path}: its table lacks the column(s) {', '.join(missing)}")
    cols = [names.index(h) if h in names else None for h in HEADINGS.values()]
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in lines
            if re.match(r"\| sc\d", line)]
    return (found.group(1) if found else "?",
            np.array([[np.nan if k is None else float(r[k]) for k in cols] for r in rows]))


def ratio(runs: list[np.ndarray], num: str, den: str) -> float:
    """Median of ``num`` over median of ``den``, the runs' scenes pooled."""
    v = np.vstack(runs)
    i, j = COLUMNS.index(num), COLUMNS.index(den)
    return float(np.median(v[:, i]) / np.median(v[:, j]))


def interval(runs: list[np.ndarray], num: str, den: str, draws: int,
             rng: np.random.Generator) -> tuple[float, float]:
    """The ratio's 5th and 95th percentiles over bootstrap draws (scenes redrawn with
    replacement within each run)."""
    got = [ratio([r[rng.integers(0, len(r), len(r))] for r in runs], num, den)
           for _ in range(draws)]
    lo, hi = np.percentile(got, [5, 95])
    return float(lo), float(hi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path,
                    default=[ROOT / "docs" / "results" / f"{n}.md" for n in RUNS])
    ap.add_argument("--draws", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=0, help="the bootstrap's")
    a = ap.parse_args()
    runs = [(p.stem, *read_run(p)) for p in a.files]
    rng = np.random.default_rng(a.seed)
    print(f"self-calibration's ratios of medians per run and pooled, each with its 90 % "
          f"bootstrap interval ({a.draws} draws); {stamp()}\n")
    print("| run | seed | scenes | " + " | ".join(r[0] for r in RATIOS) + " |\n|---|---|---|"
          + "---|" * len(RATIOS))
    def cells(vs: list[np.ndarray], bold: str = "") -> str:
        out = []
        for _, n, d in RATIOS:
            if any(np.isnan(v[:, COLUMNS.index(n)]).any() for v in vs):
                out.append("–")  # a run without priors' columns: not pooled
                continue
            lo, hi = interval(vs, n, d, a.draws, rng)
            out.append(f"{bold}{ratio(vs, n, d):.2f}{bold} ({lo:.2f}–{hi:.2f})")
        return " | ".join(out)

    for name, seed, v in runs:
        print(f"| {name} | {seed} | {len(v)} | {cells([v])} |")
    every = [v for _, _, v in runs]
    print(f"| **pooled** | | {sum(len(v) for v in every)} | {cells(every, '**')} |")
    untuned = [v for name, _, v in runs if name != TUNED]
    if 0 < len(untuned) < len(runs):
        print(f"| pooled without {TUNED} (its benches chose the JPEG foot's window) | | "
              f"{sum(len(v) for v in untuned)} | {cells(untuned)} |")


if __name__ == "__main__":
    main()
