"""Sweep the mirror's yaw and plot the target error with its 95 % ellipse.

    python examples/sweep_yaw.py [--scene scenes/default.yaml] [--yaws 12 16 20 24 28]
                                 [--width 960] [--out renders/sweep_yaw]

Each yaw is rendered, detected, solved and scored through mirrorsim's Python API; the
figure (OUT/sweep_yaw.png) shows the target error and the semi-major axis of the
solver's 95 % ellipse against the yaw.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import mirrorsim as ms
from mirrorsim.errors import RunFailed, SceneError, SolverError


def main() -> None:
    root = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=root / "scenes" / "default.yaml")
    # the default scene's target reaches the camera through the mirror from 11° to 28°
    ap.add_argument("--yaws", type=float, nargs="+", default=[12, 16, 20, 24, 28])
    ap.add_argument("--width", type=int, default=960, help="frame width in px (16:9-ish)")
    # like the command line's default folders: under the working directory
    ap.add_argument("--out", type=Path, default=Path("renders") / "sweep_yaw")
    a = ap.parse_args()
    base = ms.load_scene(a.scene)
    resolution = [a.width, int(a.width * 1088 / 1920) // 2 * 2]
    rows = []
    for yaw in a.yaws:
        # edited as its file would be: the target panel turns to face the turned mirror,
        # and every check of the scene file runs on the new yaw
        try:
            scene = ms.edit_scene(base, {"name": f"{base.name}_yaw{yaw:g}",
                                         "camera": {"resolution": resolution},
                                         "mirror": {"yaw": yaw}})
            report = ms.evaluate(scene, a.out / scene.name, progress=False, keep=())
        except (SceneError, RunFailed, SolverError) as exc:  # a yaw the bench cannot hold
            # (the scene's checks) or whose frame shows too little
            print(f"yaw {yaw:g}°: {type(exc).__name__}: {exc}")
            continue
        e = report.errors
        rows.append((yaw, e.target_cm, e.target_ellipse95_major_cm))
        print(f"yaw {yaw:g}°: target error {e.target_cm:.3f} cm, 95 % ellipse "
              f"{e.target_ellipse95_major_cm:.3f} cm")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([r[0] for r in rows], [r[1] for r in rows], "o-", label="target error")
    ax.plot([r[0] for r in rows], [r[2] for r in rows], "s--",
            label="95 % ellipse, semi-major axis")
    ax.set_xlabel("mirror yaw (°)")
    ax.set_ylabel("cm")
    ax.set_title(f"{base.name}: {resolution[0]}×{resolution[1]} px")
    ax.legend()
    fig.tight_layout()
    a.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out / "sweep_yaw.png", dpi=110)
    print(f"figure: {a.out / 'sweep_yaw.png'}")


if __name__ == "__main__":
    main()
