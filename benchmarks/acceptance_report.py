"""The Markdown summary of `benchmarks/acceptance.py`'s runs (its ``--report``): the
truth inside the 95 % ellipse with a Clopper–Pearson interval, the median Mahalanobis
distance, failures, gross errors, the same by feature, and self-calibration against
plain least squares on the same measurements."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

# the breakdown: a label and which records it holds
FEATURES = (
    ("camera farther than 83 cm from the mirror", lambda f: f["camera_to_mirror_cm"] > 83),
    ("camera 10–15 cm high", lambda f: f["camera_height"] >= 10),
    ("narrow field of view (< 45°)", lambda f: f["hfov"] < 45),
    ("wide field of view (> 75°)", lambda f: f["hfov"] > 75),
    ("a small frame (960 or 1280 px wide)", lambda f: f["width_px"] <= 1280),
    ("a pencil under 3 cm", lambda f: f["pencil_min_cm"] < 3),
    ("a pencil over 7 cm", lambda f: f["pencil_max_cm"] > 7),
    ("a beacon image under 72 px", lambda f: f["beacon_px_min"] < 72),
    ("a reflection in the glass's outer tenth", lambda f: f["glass_end"] > 0.8),
    ("a grazing mirror (line of sight < 25° from the glass)", lambda f: f["grazing_deg"] < 25),
    ("a beacon within 4 cm of the glass", lambda f: f["beacon_depth_min_cm"] < 4),
    ("two or three beacons", lambda f: f["beacons"] >= 2),
    ("one beacon", lambda f: f["beacons"] == 1),
)


def _interval(k: int, n: int) -> str:
    from scipy.stats import beta

    lo = 0.0 if k == 0 else float(beta.ppf(0.025, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(0.975, k + 1, n - k))
    return f"{lo:.2f}–{hi:.2f}"


def report(folders: list[Path]) -> str:
    """The Markdown summary of one or more runs' records."""
    runs = {}
    for folder in folders:
        recs = [json.loads(x) for x in (folder / "records.jsonl").read_text().splitlines()
                if x.strip()]
        kind = "bench" if recs and recs[0]["bench"] else "ideal"
        counts = {len(r["doc"]["beacons"]) for r in recs}
        if len(counts) == 1 and counts != {1}:  # a run of a fixed beacon count
            kind += f", {counts.pop()} beacons"
        runs[kind] = recs
    lines = ["| benches | scenes | failed to evaluate | truth inside the 95 % ellipse "
             "(95 % interval) | the ellipse's edge | median Mahalanobis (honest: the "
             "model's tail's median; Gaussian 1.18) | gross errors: an image's "
             "d_total over 1 % or α over 0.05° (an image over 6 of its σ's) | with an "
             "error-model warning |", "|---|---|---|---|---|---|---|---|"]
    for kind, recs in runs.items():
        ok = [r for r in recs if not r["failed"]]
        inside = sum(r["inside95"] for r in ok)
        med = float(np.median([r["mahalanobis"] for r in ok])) if ok else math.nan
        edge = sorted({f"{r.get('radius95', 2.4477):.2f} σ" for r in ok})
        honest = sorted({f"{r.get('radius50', 1.1774):.2f}" for r in ok})
        lines.append(f"| {kind} | {len(recs)} | {len(recs) - len(ok)} | {inside}/{len(ok)} = "
                     f"{inside / max(len(ok), 1):.3f} ({_interval(inside, len(ok))}) | "
                     f"{', '.join(edge)} | {med:.2f} ({', '.join(honest)}) | "
                     f"{_gross_cell(ok)} | "
                     f"{sum(bool(r['warnings']) for r in ok)} |")
    lines += ["", "By feature (scenes that evaluated; a scene counts under each feature it "
                  "has):", "", "| feature | " + " | ".join(f"{k}: inside / scenes" for k in runs)
              + " |", "|---|" + "---|" * len(runs)]
    for label, has in FEATURES:
        cells = []
        for recs in runs.values():
            sel = [r for r in recs if not r["failed"] and has(r["features"])]
            k = sum(r["inside95"] for r in sel)
            cells.append(f"{k}/{len(sel)} = {k / len(sel):.2f}" if sel else "–")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    multi = [r for recs in runs.values() for r in recs
             if not r["failed"] and r["features"]["beacons"] >= 2 and math.isfinite(r["plain_cm"])
             and r["bench"]]
    if multi:
        worse = [r for r in multi if r["target_cm"] > r["plain_cm"] + 0.1]
        said = [r for r in worse if r["notes"]]
        moved = [r for r in multi if any(n.startswith("self-calibration moved")
                                         for n in r["notes"])]
        shown = [r for r in moved if any("show bench errors" in n for n in r["notes"])]
        ratio = float(np.median([r["target_cm"] for r in multi])
                      / np.median([r["plain_cm"] for r in multi]))
        lines += ["", f"Self-calibration on the {len(multi)} bench scenes of two or three "
                      f"beacons (the bench model's priors) against plain least squares on "
                      f"the same measurements: median error {ratio:.2f} of plain's; "
                      f"{len(worse)} worse than plain by more than 0.1 cm, "
                      f"{len(said)} of them with a line that says why; "
                      f"{len(moved)} of the {len(multi)} say the calibration moved the "
                      f"target over 0.1 cm from plain's, {len(shown)} of them that the "
                      "beacons show the bench errors it removes"]
        lines += [f"- {r['scene']}: {r['target_cm']:.3f} cm against plain "
                  f"{r['plain_cm']:.3f} cm" + (f" ({'; '.join(r['notes'])})" if r["notes"]
                                                else " (nothing said)") for r in worse]
    failed = [r for recs in runs.values() for r in recs if r["failed"]]
    if failed:
        lines += ["", "Failed to evaluate:", ""]
        lines += [f"- {r['scene']}: {r['failed'][:200]}" for r in failed]
    gross = [r for recs in runs.values() for r in recs
             if not r["failed"] and not r["bench"] and r["gross"]]
    if gross:
        lines += ["", "Ideal benches' gross errors (an image's d_total over 1 % or α over "
                      "0.05°; its worst image, and how many of its σ's that is):", ""]
        lines += [f"- {r['scene']}: α {r['worst_alpha_deg']:.3f}°, d_total "
                  f"{r['worst_d_pct']:.2f} %"
                  + (f", {r['worst_sigma']:.1f} of its σ's" if "worst_sigma" in r else "")
                  + f"; the target {r['mahalanobis']:.2f} σ"
                  + (" (inside)" if r["inside95"] else " (outside)") for r in gross]
    return "\n".join(lines)


def _gross_cell(ok: list[dict]) -> str:
    """The gross-error cell: ideal benches only (a bench's calibration and curvature move
    a d_total by more than its image's own σ; the solve's nuisances carry those)."""
    if not ok or ok[0]["bench"]:
        return "–"
    if not all("gross_sigma" in r for r in ok):  # a run made before the σ count
        return f"{sum(r['gross'] for r in ok)} (–)"
    return f"{sum(r['gross'] for r in ok)} ({sum(r['gross_sigma'] for r in ok)})"
