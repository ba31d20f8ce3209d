"""The short human summaries that the scene commands print (the JSON carries the full
data); the analysis commands' are :mod:`mirrorsim.cli.analysis_tables`'."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mirrorsim.detection.detector import Detection
from mirrorsim.pipelines.score import Report
from mirrorsim.scene.model import Scene
from mirrorsim.truth import optics, visibility
from solver.measurements import GAUSSIAN, Tail
from solver.selfcal import SelfCalibration, describe_estimates
from solver.sltr import Solution

if TYPE_CHECKING:  # renders, budgets and tracks: no Mitsuba import to print a table
    from mirrorsim.detection.board import CameraPose
    from mirrorsim.rendering.frames import FrameFiles


def columns(rows: list[tuple[str, ...]]) -> list[str]:
    """Rows as text: the first column left-aligned, the rest right-aligned."""
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                      for k, (c, w) in enumerate(zip(r, widths, strict=True))) for r in rows]


def check_table(scene: Scene) -> str:
    """What the camera sees through the mirror, per object (``mirrorsim check``)."""
    cam, mir = scene.camera, scene.mirror
    lines = [f"{scene.name}: valid.  camera at {list(cam.position)}, height {cam.height:g} cm, "
             f"pan {cam.pan_deg:.3f}°, hfov {cam.hfov:g}°, {cam.width}×{cam.height_px} px, "
             f"fx {cam.fx:.2f} px",
             f"mirror: centre {list(mir.center)}, yaw {mir.yaw % 180:g}°, "
             f"{mir.size[0]:g} × {mir.size[1]:g} cm"
             + (f", its bottom edge {mir.z:g} cm up" if mir.z else "")
             + (f", leaning {mir.lean:g}°" if mir.lean else ""),
             f"{'object':<9} {'alpha°':>9} {'d_total':>8} {'d1':>7} {'d2':>7} "
             f"{'reflection pt':>16} {'on mirror':>9} {'u px':>7} {'h px':>6} {'seen':>5}"
             + (f" {'elev°':>7}" if scene.is_3d else "")]
    objs = [("target", scene.target)] + [(f"beacon {i}", b) for i, b in enumerate(scene.beacons)]
    for label, obj in objs:
        img = optics.object_image(scene, obj)
        ext = optics.image_extent(scene, obj)
        vis = visibility.visibility(scene, obj)
        rp = "(" + ", ".join(f"{c:.2f}" for c in img.reflection_point) + ")"
        along = optics.along_mirror(mir, img.reflection_point[:2])
        lines.append(f"{label:<9} {img.alpha_deg:9.3f} {img.d_total:8.3f} {img.d1:7.2f} "
                     f"{img.d2:7.2f} {rp:>16} {along:+9.2f} {ext.u_axis:7.1f} "
                     f"{ext.height:6.1f} {100 * vis.fraction:4.0f}%"
                     + (f" {img.elevation_deg:7.3f}" if scene.is_3d else ""))
        if vis.reason:
            lines.append(f"          {vis.reason}")
    direct = visibility.direct_view_fraction(scene, scene.target)
    lines.append("target is hidden from the camera's direct view (NLOS)" if direct == 0.0 else
                 f"target is {100 * direct:.0f}% directly visible: not NLOS")
    return "\n".join([*lines, bench_line(scene)])


def show_value(value: object) -> str:
    """An imperfection's value as written: a number, a list, a mapping; '' for none."""
    if value is None:
        return ""
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k} {v:g}" for k, v in value.items())
    return f"{value:g}"


def bench_line(scene: Scene) -> str:
    """The scene's bench imperfections in one line (its frames' errors come from them as
    well as from the detector)."""
    from mirrorsim.scene.imperfections import as_keys

    found = as_keys(scene)
    if not found:
        return "bench: ideal (no imperfections)"
    return "bench imperfections: " + ", ".join(f"{k} {show_value(v)}" for k, v in found.items())


def render_summary(scene: Scene, files: FrameFiles) -> str:
    """What ``mirrorsim render`` wrote and what the id pass saw."""
    t, r = files.truth, files.truth.render
    lines = [f"{scene.name}: {files.image} ({scene.camera.width}×{scene.camera.height_px}, "
             f"{r.spp} spp, {r.variant}, {files.seconds:.1f} s)",
             f"ground truth: {files.truth_json}"]
    for label, e in [("target", t.target)] + [(f"beacon {i}", b)
                                               for i, b in enumerate(t.beacons)]:
        bbox = None if e.bbox_px is None else list(e.bbox_px)
        lines.append(f"  {label:<9} α {e.alpha_deg:9.4f}°  d_total {e.d_total:8.3f} cm  "
                     f"in mirror: {e.visible_px} px, bbox {bbox}")
    return "\n".join(lines)


def detect_summary(frame: str, det: Detection) -> str:
    """The detector's measurements of one frame."""
    t = det.target
    d = "not measured (clipped)" if t.d_total is None else f"{t.d_total:.3f} cm"
    lines = [f"{frame}: target α {t.alpha_deg:.4f}°  d_total {d}"
             + ("  [clipped]" if t.clipped else "")]
    for i, (b, m) in enumerate(det.beacons):
        lines.append(f"  beacon {i} at {list(b.position)}: α {m.alpha_deg:.4f}°  d_total "
                     f"{m.d_total:.3f} cm (mirror image)")
    for im in det.images:
        if im.source == "direct":
            lines.append(f"  beacon {im.beacon_index} also seen directly at u = "
                         f"{im.u_axis:.1f} px (not used)")
    return "\n".join(lines)


def solution_summary(source: str, sol: Solution) -> str:
    """The mirror line and the target as ``mirrorsim solve`` prints them."""
    lines = [f"{source}: {sol.method}",
             f"  mirror  yaw {sol.mirror.yaw_deg:.4f}°  through ({sol.mirror.point[0]:.3f}, "
             f"{sol.mirror.point[1]:.3f})",
             f"  target  ({sol.target[0]:.4f}, {sol.target[1]:.4f})  reflection point "
             f"({sol.target_reflection_point[0]:.3f}, {sol.target_reflection_point[1]:.3f})"]
    if sol.covariance is not None:
        major, minor, angle = sol.ellipse95()
        lines.append(f"  95 % ellipse of the target: {major:.3f} × {minor:.3f} cm, major axis "
                     f"at {angle:.1f}°; RMS {np.sqrt(np.trace(sol.target_covariance)):.3f} cm "
                     "(first order, at the estimate; without down-weighting, the "
                     "Cramér–Rao bound there)")
    if sol.downweighted:
        lines.append("  trusted less (a Huber loss): " + ", ".join(sol.downweighted))
    if sol.nuisances:
        lines.append("  self-calibration: " + nuisance_text(sol))
    return "\n".join(lines)


# a target whose RMS error is over this share of its distance from the lens is barely
# located: its ellipse says little more than that the σ's, the priors or the beacons'
# position σ leave it loose
LOOSE_SHARE = 0.1
# nearer the lens than this (cm) a share of the distance means nothing (a target at the
# lens itself would divide by zero)
LOOSE_NEAREST_CM = 1.0


def loose_fit_warning(covariance: np.ndarray | None, target: np.ndarray,
                      observer: np.ndarray) -> str | None:
    """The warning of a target barely located (:data:`LOOSE_SHARE`), else None;
    ``covariance``: its 2×2 or 3×3 covariance (cm²), ``target`` and ``observer`` in the
    same coordinates."""
    if covariance is None:
        return None
    rms = float(np.sqrt(np.trace(np.asarray(covariance, float))))
    far = float(np.linalg.norm(np.asarray(target, float) - np.asarray(observer, float)))
    if far < LOOSE_NEAREST_CM or rms <= LOOSE_SHARE * far:
        return None
    return (f"the measurements barely locate the target: its RMS error, {rms:.3g} cm, is "
            f"{rms / far:.0%} of its distance from the lens ({far:.3g} cm); the σ's, the "
            "priors or the beacons' position σ leave it that loose")


def nuisance_text(sol: Solution) -> str:
    """Self-calibration's estimates with their σ's (from the covariance, where there)."""
    return describe_estimates(sol.nuisances, sol.nuisance_sd)


def report_table(report: Report, report_scene: Scene | None = None) -> str:
    """The compact table ``mirrorsim evaluate`` prints (with ``report_scene``, its bench
    imperfections too)."""
    t, m, s, e = report.truth, report.measurements, report.solution, report.errors
    alpha_t, d_t = m.targets[0]
    rows = [("", "truth", "measured", "estimate", "error"),
            ("target α (°)", f"{t.target.alpha_deg:.4f}", f"{alpha_t:.4f}", "",
             f"{e.target_alpha_deg:.4f}"),
            ("target d_total (cm)", f"{t.target.d_total:.3f}", f"{d_t:.3f}", "",
             f"{e.target_d_total_pct:.3f} %")]
    for i, (tb, mb) in enumerate(zip(t.beacons, m.beacons, strict=True)):
        rows.append((f"beacon {i} α (°)", f"{tb.alpha_deg:.4f}", f"{mb.alpha_deg:.4f}", "",
                     f"{e.beacon_alpha_deg[i]:.4f}"))
        rows.append((f"beacon {i} d_total (cm)", f"{tb.d_total:.3f}", f"{mb.d_total:.3f}",
                     "", f"{e.beacon_d_total_pct[i]:.3f} %"))
    rp_t, rp_e = t.target.reflection_point, s.target_reflection_point
    tp, te = t.target.position, s.target
    ellipse = s.ellipse95()  # semi-major × semi-minor
    rows += [("mirror yaw (°)", f"{t.mirror_yaw_deg:.3f}", "", f"{s.mirror.yaw_deg:.3f}",
              f"{e.mirror_yaw_deg:.3f}"),
             ("mirror line offset (cm)", "0", "", "", f"{e.mirror_offset_cm:.3f}"),
             ("reflection point (cm)", f"({rp_t[0]:.2f}, {rp_t[1]:.2f})", "",
              f"({rp_e[0]:.2f}, {rp_e[1]:.2f})", f"{e.reflection_point_cm:.3f}"),
             ("target (cm)", f"({tp[0]:.2f}, {tp[1]:.2f})", "", f"({te[0]:.2f}, {te[1]:.2f})",
              f"{e.target_cm:.3f}" + ("" if ellipse is None else
                                       f"  (95 %: {ellipse[0]:.3f} × {ellipse[1]:.3f})"))]
    lines = columns(rows)
    lines.insert(1, "-" * len(lines[0]))
    if report_scene is not None:
        lines.append(bench_line(report_scene))
    lines += _report_notes(report)
    return "\n".join(lines)


def priors_line(cal: SelfCalibration) -> str:
    """What a solve took of its bench's shared errors: each prior and the beacons'
    position σ ('' where none)."""
    if not (cal.priors or cal.position_sigma):
        return ""
    return ("the bench's shared errors estimated with their priors: "
            + ", ".join(filter(None, [cal.describe_priors(),
                                      f"beacon positions ±{cal.position_sigma:.3g} cm"
                                      if cal.position_sigma else ""])))


def pose_line(p: CameraPose) -> str:
    """The camera's pose the board gave, as a report's table says it."""
    return (f"camera pose from the board's holes: pan {p.pan_offset_deg:+.4f}° from the "
            f"mount's reading (± {p.pan_sd_deg:.4f}°), pitch {p.pitch_deg:+.4f}°, roll "
            f"{p.roll_deg:+.4f}° ({p.holes} holes, median residual {p.residual_px:.2f} px)")


def _report_notes(report: Report) -> list[str]:
    """The lines under :func:`report_table`'s table: the board's pose, the σ's, the
    priors, the images trusted less, the self-calibration, the Mahalanobis distance, the
    Cramér–Rao bound and the error as beacons are added."""
    m, s, e = report.measurements, report.solution, report.errors
    lines: list[str] = []
    if report.camera_pose is not None:
        lines.append(pose_line(report.camera_pose))
    if m.sigma is not None:
        lines.append(f"σ's from {report.error_model or 'the error model'}: "
                     f"{m.sigma.describe()}")
    lines += filter(None, [priors_line(report.self_calibration)])
    if s.downweighted:
        lines.append("trusted less by the solver (a Huber loss): " + ", ".join(s.downweighted))
    if s.nuisances:
        lines.append("self-calibration: " + nuisance_text(s))
    lines += [note if note.startswith("warning: ") else f"self-calibration: {note}"
              for note in report.calibration_notes]
    if e.target_mahalanobis is not None:
        lines.append(mahalanobis_sentence(e.target_mahalanobis, report.solution.tail))
    if e.target_crlb_cm is not None and s.target_covariance is not None:
        lines.append(f"Cramér–Rao bound of the target's RMS error: {e.target_crlb_cm:.3f} cm "
                     f"at the truth, for this estimator (its nuisances and priors) and "
                     f"Gaussian errors of these σ's (the detector's are heavier-tailed: "
                     f"its own RMS is larger); its "
                     f"covariance's RMS at the estimate: "
                     f"{np.sqrt(np.trace(s.target_covariance)):.3f} cm")
    if report.error_vs_beacons:
        lines.append("target error with the first k beacons: " + ", ".join(
            f"{k + 1}: {r.target_cm:.3f} cm ({', '.join(r.calibrated) or 'plain'})"
            for k, r in enumerate(report.error_vs_beacons)))
    return lines


def mahalanobis_sentence(distance: float, tail: Tail = GAUSSIAN) -> str:
    """Where the true target lies against the estimate's 95 % ellipse, in words that
    follow the distance: inside below the ``tail``'s 95 % radius (χ₂'s by default),
    outside beyond it."""
    r95 = tail.radius(0.95)
    where = (f"inside the 95 % ellipse, whose edge is at {r95:.2f} σ" if distance <= r95
             else f"outside the 95 % ellipse, whose edge is at {r95:.2f} σ")
    return f"the true target lies {distance:.2f} σ from the estimate: {where}"
