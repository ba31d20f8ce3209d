"""3-D scenes rendered end to end: the 3-D solve beside the planar solve on the same
frames, on scenes drawn here (never the project's own specs).

    python benchmarks/evaluate3d.py [--scenes 40] [--seed S] [--out DIR] [--report]
                                    [--error-model FILE]
    python benchmarks/evaluate3d.py --dataset DIR    # a 3-D dataset's rows, as a table
    python benchmarks/evaluate3d.py --acceptance DIR... [--error-model FILE]  # a line each

Each scene is drawn at random and kept where ``check`` accepts it with every image
whole (a clipped image is refused by the detector, not a 3-D question):
- the board 80 × 80 cm, the camera at its corner (0–4 cm in), 6–12 cm up, a 58–70°
  field, 1920 × 1088 px, panned to the mirror;
- a mirror 22–28 × 18–24 cm, 30–40 cm out along y = 58–66, at yaw 8–32°, leaning by
  the row's lean (0 or ±1–4°, its sign drawn);
- the target panel (9–11 × 8–11 cm) behind the default scene's wall, raised 0–15 cm;
- one to three pencils (4.5–7 cm) 7–14 cm before the glass, raised 0–15 cm.

Each is evaluated as ``mirrorsim evaluate --geometry 3d`` does (the shipped ideal
model, 8 spp).  Printed: per lean, the 3-D solve's median and largest target error,
its median height error, how often its 95 % ellipsoid holds the truth, and the planar
solve's median error (in plan) on the same frames, and the median Mahalanobis distance
(χ₃'s median is 1.54: below it, the ellipsoids are wider than the errors).
``--report`` reads the rows of a finished run.  Markdown (docs/regenerate.py stamps it).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from clone import ROOT  # noqa: F401 (puts the repository on the path)

from mirrorsim.errors import InputError
from mirrorsim.formats.error_model_file import load_error_model
from mirrorsim.pipelines.evaluate3d import CHI2_3_R95, SIGMA3_FACTORS, evaluate_into3
from mirrorsim.pipelines.scenes import scene_from_dict

LEANS = (0.0, 1.0, 2.0, 3.0, 4.0)


def draw(rng: np.random.Generator, k: int) -> dict:
    """One scene's file keys (docs/scenes.md)."""
    lean = float(LEANS[k % len(LEANS)] * rng.choice((-1.0, 1.0)))
    cx, cy = rng.uniform(30, 40), rng.uniform(58, 66)
    yaw = rng.uniform(8, 32)
    u = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw))])
    n = np.array([u[1], -u[0]])  # the face towards the board's near corner
    beacons = []
    for _ in range(int(rng.integers(1, 4))):
        p = np.array([cx, cy]) + u * rng.uniform(-7, 7) + n * rng.uniform(7, 14)
        beacons.append({"position": [round(float(p[0]), 2), round(float(p[1]), 2),
                                     round(float(rng.uniform(0, 15)), 2)],
                        "height": round(float(rng.uniform(4.5, 7)), 2)})
    return {
        "name": f"s3d{k:04d}",
        "board": {"size": [80, 80], "hole_pitch": 2.5},
        "camera": {"position": [round(float(rng.uniform(0, 4)), 2),
                                round(float(rng.uniform(0, 4)), 2)],
                   "height": round(float(rng.uniform(6, 12)), 2),
                   "resolution": [1920, 1088], "hfov": round(float(rng.uniform(58, 70)), 2),
                   "pan": "mirror"},
        "mirror": {"center": [round(cx, 2), round(cy, 2)], "yaw": round(yaw, 2),
                   "size": [round(float(rng.uniform(22, 28)), 2),
                            round(float(rng.uniform(18, 24)), 2)], "lean": lean},
        "target": {"position": [round(float(rng.uniform(52, 60)), 2),
                                round(float(rng.uniform(45, 52)), 2),
                                round(float(rng.uniform(0, 15)), 2)],
                   "size": [round(float(rng.uniform(9, 11)), 2),
                            round(float(rng.uniform(8, 11)), 2)]},
        "beacons": beacons,
        "occluders": [{"start": [30, 34.5], "end": [38.5, 25], "height": 30}],
    }


def draw_wide(rng: np.random.Generator, k: int) -> dict:
    """One scene drawn wider than :func:`draw`, across more of what ``check`` accepts
    (the acceptance set: nothing was fitted or mended on it): a board 60–120 cm, the
    camera anywhere 0–15 cm in from its corner, 4–15 cm up, a 40–85° field at 1920,
    1280 or 960 px, panned to the mirror or the target; the mirror 40–90 cm out, seen
    15–75° from square-on, 18–35 × 14–26 cm, its bottom edge raised 0–3 cm in a quarter
    of the scenes; pencils 3–8 cm tall 4–15 cm before the glass; the panel 6–12 × 6–14
    cm; a wall across the camera's direct line to the target."""
    lean = float(LEANS[k % len(LEANS)] * rng.choice((-1.0, 1.0)))
    size = float(rng.uniform(60, 120))
    cam = rng.uniform(0, 15, 2)
    bearing = math.radians(rng.uniform(40, 70))
    dist = rng.uniform(40, 90)
    c = cam + dist * np.array([math.cos(bearing), math.sin(bearing)])
    # the face's normal turned 15-75° from the ray back to the camera
    back = math.degrees(bearing) + 180.0 + rng.choice((-1, 1)) * rng.uniform(15, 75)
    n = np.array([math.cos(math.radians(back)), math.sin(math.radians(back))])
    u = np.array([-n[1], n[0]])
    w, h = float(rng.uniform(18, 35)), float(rng.uniform(14, 26))

    def before(along: float, out: float) -> np.ndarray:
        return c + u * along + n * out

    beacons = [{"position": [*np.round(before(rng.uniform(-w / 2 + 2, w / 2 - 2),
                                                rng.uniform(4, 15)), 2).tolist(),
                             round(float(rng.uniform(0, 15)), 2)],
                "height": round(float(rng.uniform(3, 8)), 2)}
               for _ in range(int(rng.integers(1, 4)))]
    t = before(rng.uniform(-w / 2, w / 2), rng.uniform(15, 35))
    tw, th, tz = float(rng.uniform(6, 12)), float(rng.uniform(6, 14)), float(rng.uniform(0, 15))
    mid = (cam + t) / 2  # a wall across the direct line, at its middle
    ray = (t - cam) / np.linalg.norm(t - cam)
    across = np.array([-ray[1], ray[0]]) * (tw / 2 + 3)
    res = [[1920, 1088], [1280, 720], [960, 544]][int(rng.integers(0, 3))]
    return {
        "name": f"w3d{k:04d}",
        "board": {"size": [round(size, 2), round(size, 2)], "hole_pitch": 2.5},
        "camera": {"position": np.round(cam, 2).tolist(),
                   "height": round(float(rng.uniform(4, 15)), 2), "resolution": res,
                   "hfov": round(float(rng.uniform(40, 85)), 2),
                   "pan": str(rng.choice(("mirror", "target")))},
        "mirror": {"center": [*np.round(c, 2).tolist(),
                              round(float(rng.uniform(0, 3)) if k % 4 == 3 else 0.0, 2)],
                   "yaw": round(math.degrees(math.atan2(u[1], u[0])), 2),
                   "size": [round(w, 2), round(h, 2)], "lean": lean},
        "target": {"position": [*np.round(t, 2).tolist(), round(tz, 2)],
                   "size": [round(tw, 2), round(th, 2)]},
        "beacons": beacons,
        "occluders": [{"start": np.round(mid - across, 2).tolist(),
                       "end": np.round(mid + across, 2).tolist(),
                       "height": round(tz + th + 10, 2)}],
    }


def scenes(seed: int, count: int, *, wide: bool = False):
    """``count`` scenes ``check`` accepts with every image whole (drawn by :func:`draw`,
    or :func:`draw_wide`), and how many draws were refused."""
    rng = np.random.default_rng(seed)
    out, refused, k = [], 0, 0
    while len(out) < count:
        d = (draw_wide if wide else draw)(rng, k)
        k += 1
        try:
            s = scene_from_dict(d)
        except InputError:
            refused += 1
            continue
        if any("clipped" in w or "cannot tell" in w for w in s.warnings):
            refused += 1
            continue
        out.append(s)
    return out, refused


def _rows(out: Path, model: Path | None) -> Path:
    """Where a run's rows go: ``rows/``, or with a model of its own ``rows-<its stem>/``
    (the frames, rendered once, are the same)."""
    return out / ("rows" if model is None else f"rows-{model.stem}")


def run(args) -> Path:
    out = Path(args.out or f"renders/evaluate3d-{'wide-' if args.wide else ''}{args.seed}")
    model = None if args.error_model is None else load_error_model(args.error_model)
    factors = ({k: (1.0, 1.0, 1.0) for k in SIGMA3_FACTORS} if model and model.three_d
               else SIGMA3_FACTORS)
    _rows(out, args.error_model).mkdir(parents=True, exist_ok=True)
    chosen, refused = scenes(args.seed, args.scenes, wide=args.wide)
    (out / "drawn.json").write_text(json.dumps({"refused": refused}))
    for i, s in enumerate(chosen):
        row = _rows(out, args.error_model) / f"{s.name}.json"
        if row.exists():  # resumed: a finished scene is kept
            continue
        try:
            r = evaluate_into3(s, out / "frames", progress=False, keep=(), error_model=model)
            doc = {"lean": s.mirror.lean, "errors": r.errors.to_json(),
                   "beacons": len(s.beacons), "measurements": r.seen.to_json(),
                   "sigma_factors": factors}
        except Exception as exc:  # noqa: BLE001 (a failed scene is a result, said)
            doc = {"lean": s.mirror.lean, "failed": f"{type(exc).__name__}: {exc}"[:300]}
        row.write_text(json.dumps(doc))
        print(f"{i + 1}/{len(chosen)} {s.name}", file=sys.stderr, flush=True)
    return out


HEADER = ["| lean | scenes | 3-D median (cm) | 3-D max (cm) | height median (cm) | "
          "inside the 95 % ellipsoid | median Mahalanobis (honest 1.54) | "
          "planar median (cm, in plan) |",
          "|---|---|---|---|---|---|---|---|"]


def _line(name: str, rs: list) -> str:
    """One row of the table: ``rs``' errors blocks (Score3's JSON)."""
    if not rs:
        return f"| {name} | 0 | | | | | | |"
    e = np.array([r["errors"]["target_cm"] for r in rs])
    h = np.array([abs(r["errors"]["target_height_cm"]) for r in rs])
    inside = sum(r["errors"]["target_mahalanobis"] <= CHI2_3_R95 for r in rs)
    planar = [r["errors"]["planar_target_cm"] for r in rs
              if r["errors"]["planar_target_cm"] is not None]
    maha = np.median([r["errors"]["target_mahalanobis"] for r in rs])
    return (f"| {name} | {len(rs)} | {np.median(e):.3f} | {e.max():.3f} | "
            f"{np.median(h):.3f} | {inside}/{len(rs)} = {inside / len(rs):.2f} | "
            f"{maha:.2f} | " + (f"{np.median(planar):.3f} |" if planar else " |"))


def report(out: Path, model: Path | None = None) -> str:
    rows = [json.loads(p.read_text()) for p in sorted(_rows(out, model).glob("*.json"))]
    refused = json.loads((out / "drawn.json").read_text())["refused"]
    ok = [r for r in rows if "errors" in r]
    lines = [f"{len(rows)} scenes ({refused} draws refused by `check` or clipped); "
             f"{len(rows) - len(ok)} failed to evaluate", "", *HEADER]
    for lean in LEANS:
        lines.append(_line(f"{lean:g}°", [r for r in ok if abs(abs(r["lean"]) - lean) < 1e-9]))
    lines.append(_line("leaning (1–4°)", [r for r in ok if r["lean"] != 0]))
    lines.append(_line("all", ok))
    for r in rows:
        if "failed" in r:
            lines.append(f"- failed (lean {r['lean']:g}°): {r['failed']}")
    return "\n".join(lines)


def _dataset_rows(folder: Path) -> tuple[dict, list[dict]]:
    """A 3-D dataset's table, and its solved rows as :func:`_line` takes them."""
    from mirrorsim.formats.dataset_folder import read_table

    try:
        cols = read_table(folder)
    except InputError as exc:
        sys.exit(f"error: {exc}")
    return cols, [{"lean": cols["mirror_lean_deg"][i], "errors": {
        "target_cm": cols["err_target_cm"][i],
        "target_height_cm": cols["err_target_height_cm"][i],
        "target_mahalanobis": cols["target_mahalanobis"][i],
        "planar_target_cm": cols["planar_err_target_cm"][i]}}
        for i in range(len(cols["index"]))
        if not cols["error"][i] and cols["geometry"][i] == "3d"]


def acceptance(folders: list[Path], model: Path | None) -> str:
    """One line per acceptance set (a run's folder, its rows with ``model``; or a 3-D
    dataset's folder), all its scenes together."""
    lines = HEADER[:]
    for folder in folders:
        if (folder / "dataset.parquet").exists():
            rows = _dataset_rows(folder)[1]
        else:
            found = sorted(_rows(folder, model).glob("*.json"))
            if not found:
                sys.exit(f"error: {folder}: neither a 3-D dataset nor a finished run's rows "
                         f"({_rows(folder, model).name}/)")
            rows = [r for r in (json.loads(p.read_text()) for p in found) if "errors" in r]
        lines.append(_line(folder.name, rows))
    return "\n".join(lines).replace("| lean |", "| set |", 1)


def dataset_report(folder: Path) -> str:
    """The table of a 3-D dataset's rows (``mirrorsim dataset --spec
    scenes/dataset_spec_3d.yaml``), its leans drawn from a range: binned by |lean|."""
    cols, rows = _dataset_rows(folder)
    n = len(cols["index"])
    lines = [f"{n} scenes; {n - len(rows)} failed or not solved in 3-D", "", *HEADER]
    for lo in range(4):
        name = f"{lo}–{lo + 1}°" if lo else "under 1°"
        lines.append(_line(name, [r for r in rows if lo <= abs(r["lean"]) < lo + 1]))
    steep = [r for r in rows if abs(r["lean"]) >= 4]  # (a spec may lean the glass to 10°)
    if steep:
        lines.append(_line("4° or more", steep))
    lines.append(_line("all", rows))
    for i in range(n):
        if cols["error"][i]:
            lines.append(f"- {cols['scene'][i]} failed: {cols['error'][i]}")
    return "\n".join(lines)


def residuals(outs: list[Path]) -> str:
    """Each reading's error against what an exact detector reads, in its σ's as the
    planar error model gives them (the factors in force divided out), per kind: their
    RMS, their 95th and 97.5th percentiles, and the factor that puts 97.5 % of them
    within 1.96 σ, none below 1 (:data:`~mirrorsim.pipelines.evaluate3d.SIGMA3_FACTORS`:
    the errors' tails are heavier than a Gaussian's, so the σ's are widened for them,
    never narrowed)."""
    names = ("α", "elevation", "d_total")
    acc: dict[tuple[str, int], list[float]] = {}
    for out in outs:
        if not any((out / "rows").glob("*.json")):
            sys.exit(f"error: {out}: no finished run's rows (rows/)")
        for p in sorted((out / "rows").glob("*.json")):
            r = json.loads(p.read_text())
            if "errors" not in r:
                continue
            m, exact = r["measurements"], r["errors"]["exact_readings"]
            seen = [*m["beacons"], m["target"]]
            for i, (g, x, s) in enumerate(zip(seen, exact, m["sigma"], strict=True)):
                kind = "target" if i == len(seen) - 1 else "beacon"
                f = r["sigma_factors"][kind]
                for k, key in enumerate(("alpha_deg", "elevation_deg", "d_total")):
                    sk = (s["alpha_deg"], s["elevation_deg"], s["d_total_rel"] * x["d_total"])[k]
                    acc.setdefault((kind, k), []).append((g[key] - x[key]) / (sk / f[k]))
    lines = ["| image | reading | n | RMS (σ) | 95th percentile (σ) | 97.5th (σ) | factor |",
             "|---|---|---|---|---|---|---|"]
    for (kind, k), v in sorted(acc.items()):
        a = np.abs(v)
        q95, q975 = (float(np.quantile(a, q)) for q in (0.95, 0.975))
        lines.append(f"| {kind} | {names[k]} | {len(a)} | {np.sqrt(np.mean(a**2)):.2f} | "
                     f"{q95:.2f} | {q975:.2f} | {max(1.0, q975 / 1.96):.2f} |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", type=int, default=40)
    p.add_argument("--seed", type=int, default=61206302)
    p.add_argument("--out", default=None)
    p.add_argument("--report", action="store_true", help="only print the finished rows")
    p.add_argument("--wide", action="store_true",
                   help="draw the scenes wider, across more of what check accepts "
                        "(draw_wide): the acceptance set")
    p.add_argument("--residuals", nargs="+", type=Path, metavar="DIR",
                   help="print the σ factors the runs in DIR... call for, and stop")
    p.add_argument("--error-model", type=Path, metavar="FILE",
                   help="evaluate with this model (a 3-D model's own σ's; default the "
                        "shipped one), its rows in DIR/rows-<its name>/ beside the frames")
    p.add_argument("--dataset", type=Path, metavar="DIR",
                   help="print the table of a 3-D dataset's rows (`mirrorsim dataset "
                        "--spec scenes/dataset_spec_3d.yaml`), and stop")
    p.add_argument("--acceptance", nargs="+", type=Path, metavar="DIR",
                   help="print one line per finished set (runs' folders with --error-model's "
                        "rows, or 3-D datasets), and stop")
    args = p.parse_args()
    if args.acceptance:
        print(acceptance(args.acceptance, args.error_model))
        return
    if args.residuals:
        print(residuals(args.residuals))
        return
    if args.dataset:
        print(dataset_report(args.dataset))
        return
    out = Path(args.out or f"renders/evaluate3d-{'wide-' if args.wide else ''}{args.seed}")
    if not args.report:
        out = run(args)
    print(report(out, args.error_model))


if __name__ == "__main__":
    main()
