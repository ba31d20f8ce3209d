"""The table ``mirrorsim evaluate`` prints for a 3-D report (the JSON carries the full
data): each image's α, elevation and d_total, the mirror's yaw and lean, the target
in 3-D and its height, the planar solve of the same frames beside it."""

from __future__ import annotations

import numpy as np

from mirrorsim.cli.tables import bench_line, columns, pose_line, priors_line
from mirrorsim.pipelines.evaluate3d import CHI2_3_R95, Report3
from mirrorsim.scene.model import Scene
from solver.lsq3 import Fit3
from solver.selfcal import KNOWN, describe_estimates


def _xyz(p) -> str:
    return "(" + ", ".join(f"{float(c):.2f}" for c in p) + ")"


def report3_table(report: Report3, report_scene: Scene | None = None) -> str:
    """The compact table of a 3-D evaluation (with ``report_scene``, its bench line)."""
    t, s, f, e = report.truth, report.seen, report.fit, report.errors
    rows = [("", "truth", "measured", "estimate", "error")]
    exact = e.exact_readings  # what an exact detector reads: the beacons', the target's
    objs = [("target", exact[-1], s.target)] + [
        (f"beacon {i}", ex, sb) for i, (ex, (_, sb)) in enumerate(zip(exact, s.beacons,
                                                                      strict=False))]
    for name, true, seen in objs:
        rows += [(f"{name} α (°)", f"{true[0]:.4f}", f"{seen[0]:.4f}", "",
                  f"{abs(seen[0] - true[0]):.4f}"),
                 (f"{name} elevation (°)", f"{true[1]:.4f}", f"{seen[1]:.4f}", "",
                  f"{abs(seen[1] - true[1]):.4f}"),
                 (f"{name} d_total (cm)", f"{true[2]:.3f}", f"{seen[2]:.3f}", "",
                  f"{100 * abs(seen[2] - true[2]) / true[2]:.3f} %")]
    tp = np.asarray(t.target.position, float)
    tp = tp if len(tp) == 3 else np.r_[tp, 0.0]
    axes = _ellipsoid95(f.target_covariance)
    rows += [("mirror yaw (°)", f"{t.mirror_yaw_deg:.3f}", "", f"{f.plane.yaw_deg:.3f}",
              f"{e.mirror_yaw_deg:.3f}"),
             ("mirror lean (°)", f"{t.mirror.lean:.3f}", "", f"{f.plane.lean_deg:.3f}",
              f"{abs(e.mirror_lean_deg):.3f}"),
             ("target (cm)", _xyz(tp), "", _xyz(f.target),
              f"{e.target_cm:.3f}  (95 %: " + " × ".join(f"{a:.3f}" for a in axes) + ")"),
             ("target height (cm)", f"{tp[2]:.3f}", "", f"{f.target[2]:.3f}",
              f"{abs(e.target_height_cm):.3f}")]
    lines = columns(rows)
    lines.insert(1, "-" * len(lines[0]))
    if report_scene is not None:
        lines.append(bench_line(report_scene))
    if report.camera_pose is not None:
        lines.append(pose_line(report.camera_pose))
    lines.append("the images' truth: what an exact detector reads (in a leaning mirror "
                 "the image leans: its mid-height's bearing, its length along its axis)")
    lines.append(f"solved in 3-D; σ's from {report.error_model} " + (
        "(the elevation's from each image's d_total σ)" if report.ellipsoid_scale is None
        else f"(its own elevation laws; the covariance widened ×{report.ellipsoid_scale:.2f} "
             "for the errors' tails, beyond the Cramér–Rao bound's σ's)"))
    if report.planar_target is not None and e.planar_target_cm is not None:
        lines.append(f"the planar solve of the same frames: target ({report.planar_target[0]:.2f}, "
                     f"{report.planar_target[1]:.2f}), {e.planar_target_cm:.3f} cm off in plan "
                     f"(the 3-D solve: {e.target_plan_cm:.3f} cm)")
    lines += filter(None, [priors_line(report.self_calibration)])
    if f.downweighted:
        lines.append("trusted less by the solver (a Huber loss): " + ", ".join(f.downweighted))
    if f.nuisances:
        lines.append("the bench's shared errors estimated (with their priors; ± each "
                     "estimate's σ after the fit): "
                     + describe_estimates(*_nuisances(f)))
    where = "inside" if e.inside95 else "outside"
    lines.append(f"the true target lies {e.target_mahalanobis:.2f} σ from the estimate: "
                 f"{where} the 95 % ellipsoid, whose edge is at {CHI2_3_R95:.2f} σ")
    if e.target_crlb_cm is not None:
        lines.append(f"Cramér–Rao bound of the target's RMS error: {e.target_crlb_cm:.3f} cm "
                     f"at the truth; its covariance's RMS at the estimate: "
                     f"{e.target_covariance_rms_cm:.3f} cm")
    return "\n".join(lines)


def solution3_summary(source: str, fit: Fit3) -> str:
    """A 3-D solution as ``mirrorsim solve`` prints it."""
    p = fit.plane
    lines = [f"{source}: 3-D weighted least squares",
             f"  mirror  yaw {p.yaw_deg:.4f}°  lean {p.lean_deg:+.4f}°  plane n·x = "
             f"{p.rho:.3f} cm, n = {_xyz(p.normal)}",
             f"  target  {_xyz(fit.target)}"]
    axes = _ellipsoid95(fit.target_covariance)
    if axes:
        lines.append("  95 % ellipsoid of the target: " + " × ".join(f"{a:.3f}" for a in axes)
                     + " cm (semi-axes)")
    if fit.nuisances:
        lines.append("  self-calibration (each estimate ± its σ after the fit): "
                     + describe_estimates(*_nuisances(fit)))
    if fit.downweighted:
        lines.append("  trusted less (a Huber loss): " + ", ".join(fit.downweighted))
    return "\n".join(lines)


def _ellipsoid95(cov: np.ndarray | None) -> tuple[float, ...]:
    """The 95 % ellipsoid's semi-axes (cm), largest first."""
    if cov is None:
        return ()
    vals = np.linalg.eigvalsh(np.asarray(cov, float))[::-1]
    return tuple(float(CHI2_3_R95 * np.sqrt(max(v, 0.0))) for v in vals)


def _nuisances(fit: Fit3) -> tuple[dict[str, float], dict[str, float]]:
    """The fit's nuisance estimates and their σ's (where it has a covariance), keyed by
    their names in a solution (:data:`solver.selfcal.KNOWN`), as describe_estimates
    says them."""
    sd = fit.nuisance_sd or {}
    return ({KNOWN[n][0]: v for n, v in fit.nuisances.items()},
            {KNOWN[n][0]: s for n, s in sd.items()})
