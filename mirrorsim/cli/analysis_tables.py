"""The analysis commands' printed summaries: the error budget, Table 1, a plan, a track
and an error model (the JSON carries the full data)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mirrorsim.cli.tables import columns, show_value
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.error_model_scope import SIGMA_FEATURES
from mirrorsim.scene.model import Scene
from solver.measurements import Tail
from solver.montecarlo import Table1
from solver.montecarlo3 import Table3, layout3
from solver.selfcal import describe_priors

if TYPE_CHECKING:  # budgets, plans and tracks run renders: no Mitsuba import to print one
    from mirrorsim.pipelines.budget import Budget
    from mirrorsim.pipelines.planning import Plan
    from mirrorsim.pipelines.track_report import TrackReport
    from solver.beacon_set import BeaconSet


# a row's RMSE is called unsettled where its largest draw holds more than this share of
# the summed squared error
HEAVY_TAIL_SHARE = 0.5


def budget_table(budget: Budget) -> str:
    """The table ``mirrorsim budget`` prints: each source's measured deltas (a labelled
    column per beacon), the target error it leaves, the first-order prediction and, with
    self-calibration, the self-calibrated target error."""
    def signed(x: float, digits: int) -> str:
        return f"{x:+.{digits}f}"

    nb = max((len(c.delta.beacon_alpha_deg) for c in (*budget.sources, budget.all)
              if c is not None and c.delta is not None), default=1)
    cal = bool(budget.calibration.nuisances)
    three = budget.geometry == "3d"  # each image's elevation beside its α
    quantities = ("α", "ε", "d") if three else ("α", "d")
    unit = {"α": "°", "ε": "°", "d": "%"}
    rows = [("source", "value", *(f"Δ{q}_t ({unit[q]})" for q in quantities),
             *(f"Δ{q}_b{i} ({unit[q]})" for i in range(nb) for q in quantities),
             "moved (cm)", "1st order", "target (cm)", "1st order",
             *(["self-cal (cm)"] if cal else []))]
    failures = []

    def image(a: float, e: float | None, p: float) -> tuple[str, ...]:  # one image's cells
        return (signed(a, 4), *((signed(e, 4),) if three else ()), signed(p, 3))

    for c in (*budget.sources, *([budget.all] if budget.all else [])):
        d = c.delta
        value = show_value(c.value)
        if c.failed:
            rows.append((c.source, value, "failed", *[""] * (len(rows[0]) - 3)))
            failures.append(f"  {c.source}: {c.failed}")
            continue
        own = image(d.target_alpha_deg, d.target_elevation_deg, d.target_d_total_pct)
        per = [x for a, e, p in zip(d.beacon_alpha_deg, d.beacon_elevation_deg
                                    or (None,) * len(d.beacon_alpha_deg),
                                    d.beacon_d_total_pct, strict=True) for x in image(a, e, p)]
        rows.append((c.source, value, *own, *per,
                     *[""] * (len(quantities) * nb - len(per)),
                     f"{c.shift_cm:.2f}", f"{c.predicted_shift_cm:.2f}",
                     f"{c.target_cm:.2f}", f"{c.predicted_cm:.2f}",
                     *([_cm(c.calibrated_cm)] if cal else [])))
    lines = columns(rows)
    lines.insert(1, "-" * len(lines[0]))
    head = (f"{budget.scene}: ideal bench {budget.ideal_cm:.2f} cm"
            + (" (solved in 3-D; errors are 3-D distances)" if three else ""))
    if cal:
        head += (f" ({_cm(budget.ideal_calibrated_cm)} cm self-calibrated for "
                 f"{' and '.join(budget.calibration.nuisances)}"
                 + (f", beacons known to {budget.calibration.position_sigma:g} cm"
                    if budget.calibration.position_sigma else "")
                 + (f", priors {budget.calibration.describe_priors()}"
                    if budget.calibration.priors else "") + ")")
    lines.insert(0, head + "; each source alone" + (", then all together" if budget.all else ""))
    return "\n".join(lines + failures)


def _cm(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def montecarlo_table(res: Table1) -> str:
    """Table 1 of the paper beside ours (``mirrorsim montecarlo``)."""
    g, lay = res.geometry, res.geometry.layout()
    lines = [f"Table 1 protocol: {res.iterations} draws per row; target at alpha "
             f"{g.alpha_deg:g}°, d_total {g.d_total:g}; mirror through "
             f"({lay.mirror_point[0]:.3f}, {lay.mirror_point[1]:.3f}) at yaw "
             f"{lay.yaw_deg:.1f}°; beacon at ({lay.beacon[0]:.3f}, {lay.beacon[1]:.3f})",
             "σ_α: the angle's standard deviation (deg); σ_d: d_total's, in % of d_total "
             "(the paper's absolute σ_d divided by d_total); RMSEs in the table's distance "
             "units",
             f"{'σ_α (°)':>9} {'σ_d (%)':>7} | {'paper ref':>9} {'paper tar':>9} | "
             f"{'ours ref':>9} {'ours tar':>9} {'yaw (deg)':>9}"]
    d_total, d_b = g.d_total, lay.beacon_d
    for r in res.rows:
        rel_t = r.sigma_d / d_total
        beacon = ""
        if r.beacon_sigma is not None and not np.allclose(
                (r.beacon_sigma[0], r.beacon_sigma[1] / d_b), (r.sigma_alpha_deg, rel_t)):
            beacon = (f"  (the target's σ's; the beacon's {r.beacon_sigma[0]:.4g}°, "
                      f"{100 * r.beacon_sigma[1] / d_b:.4g} %)")
        lines.append(f"{r.sigma_alpha_deg:9.4g} {100 * rel_t:7.4g} | "
                     f"{r.paper_rmse_ref:9.3f} {r.paper_rmse_tar:9.3f} | "
                     f"{r.ours.rmse_ref:9.3f} {r.ours.rmse_tar:9.3f} "
                     f"{r.ours.rmse_yaw_deg:9.2f}" + beacon)
    for i, r in enumerate(res.rows, 1):
        for what, share, median, why in (
                ("reflector", r.ours.largest_share_ref, r.ours.median_ref,
                 " (a mirror estimated nearly along the target's ray meets it far off)"),
                ("target", r.ours.largest_share_tar, r.ours.median_tar, "")):
            if share > HEAVY_TAIL_SHARE:
                lines.append(
                    f"note: row {i}: one draw of {res.iterations} holds {100 * share:.0f} % of "
                    f"the {what}'s squared error{why}, so its RMSE follows that draw and does "
                    f"not settle as draws grow; its median error is {median:.3f}")
    return "\n".join(lines)


def montecarlo3_table(res: Table3) -> str:
    """The Table 1 protocol in 3-D (``mirrorsim montecarlo --lean …``): each row's
    RMSEs, the 3-D solve's beside the planar solve's of the same draws."""
    r, lay = res.rise, layout3(res.geometry, res.rise)
    (ta, te, td), (ba, be, bd) = lay.target_seen, lay.beacon_seen
    lines = [f"Table 1 protocol in 3-D: {res.iterations} draws per row; mirror leaning "
             f"{r.lean_deg:g}° at yaw {lay.plane.yaw_deg:.1f}°; camera {r.camera_z:g} up; "
             f"target {r.target_z:g} up, seen at alpha {ta:.3f}°, elevation {te:.3f}°, "
             f"d_total {td:.4g}; beacon {r.beacon_z:g} up, at {ba:.3f}°, {be:.3f}°, {bd:.4g}",
             "σ_α and σ_ε (each image's elevation; σ_α's unless --sigma-elevation) in deg; "
             "σ_d in % of d_total; RMSEs in the table's units (the 3-D solve's in 3-D, the "
             "planar solve's target in plan)",
             f"{'σ_α (°)':>9} {'σ_d (%)':>7} | {'3-D ref':>9} {'3-D tar':>9} {'yaw (°)':>8} "
             f"{'lean (°)':>8} | {'planar tar':>10} | {'failed':>6}"]
    for row, e in res.rows:
        lines.append(f"{row[0]:9.4g} {100 * row[1] / td:7.4g} | {e.rmse_ref:9.3f} "
                     f"{e.rmse_tar:9.3f} {e.rmse_yaw_deg:8.2f} {e.rmse_lean_deg:8.2f} | "
                     f"{e.rmse_tar_planar:10.3f} | {e.failed:6d}")
    return "\n".join(lines)


def plan_text(scene: Scene, plan: Plan) -> str:
    """The placement analysis as ``mirrorsim plan`` prints it."""
    p, q, L, bb = plan.geometry, plan.geometry_corrected, plan.path_lengths, plan.best
    return "\n".join([
        f"{scene.name}: target alpha {plan.target_alpha_deg:.3f}°, d_total "
        f"{plan.target_d_total:.2f} cm, mirror {scene.mirror.size[0]:g} cm wide, "
        f"eps ±{plan.eps_deg:g}°",
        f"  paper (eqs 9-18): step b = {p.b:.3f} cm, a/2 = {p.half_a:.3f} cm, "
        f"triangle {p.area:.2f} cm², N_bea = 2·d_total/b = {p.n_beacons:.1f}",
        f"  eq 15 with the line perpendicular to the observation line (as its text says): "
        f"a/2 = {q.half_a:.3f} cm",
        f"  exact region seen for every orientation: {plan.region.area:.0f} cm²; "
        "area vs d_total (paper / exact): " + ", ".join(
            f"{d:g}: {a:.2f}/{e:.0f}" for d, a, e in zip(*plan.area_vs_d, strict=True)),
        f"  paths over {plan.n_steps} steps: linear {L['linear']:.1f}, rectangular "
        f"{L['rectangular']:.1f}, saw-tooth {L['sawtooth']:.1f} cm",
        f"  expected target RMSE at {plan.sigma.describe()} over {plan.n_poses} mirror poses:",
        *(f"    scene's beacon {i} {list(b.position)} alone: {rmse:.3f} cm (seen under "
          f"{100 * seen:.0f}% of poses)"
          for i, (b, (rmse, seen)) in enumerate(zip(scene.beacons, plan.scene_beacons,
                                                    strict=True))),
        f"    best position ({bb.position[0]:.1f}, {bb.position[1]:.1f}): "
        f"{bb.rmse:.3f} cm" + (f" (seen under {100 * bb.seen_fraction:.0f}% of poses: none "
                               "seen under all passes the placement's test)"
                               if bb.seen_fraction < 1 else ""),
        *_set_lines(plan.beacon_set), *_height_lines(plan)])


def _height_lines(plan: Plan) -> list[str]:
    """A 3-D scene's posts: the best height at each position, beside the board's."""
    if not plan.heights:
        return []
    top = max(max(h.heights, default=0.0) for h in plan.heights)
    out = [f"  posts (3-D; σ_ε = σ_α): the target's 3-D RMS bound with a beacon alone, on the "
           f"board and on its best post of 0–{top:g} cm whose image the glass shows whole:"]
    for h in plan.heights:
        best = h.best
        floor = dict(zip(h.heights, h.rmse, strict=True)).get(0.0)
        out.append(f"    at ({h.position[0]:.1f}, {h.position[1]:.1f}): "
                   + ("no post shows it whole" if best is None else
                      f"{best[1]:.3f} cm with a post of {best[0]:g} cm"
                      + (f" ({floor:.3f} cm on the board)" if floor is not None else "")))
    return out


def _set_lines(bs: BeaconSet | None) -> list[str]:
    """What each planned beacon buys."""
    if bs is None:
        return []
    nu = " and ".join(bs.calibration.nuisances)
    priors = describe_priors(dict(bs.calibration.priors))
    out = [f"  {len(bs.positions)} beacons, chosen one at a time"
           + (f" with {nu} estimated alongside (self-calibration"
              + (f"; priors {priors}" if priors else "") + ")" if nu else "") + ":"]
    for k, (pos, after, plain) in enumerate(zip(bs.positions, bs.rmse, bs.rmse_plain,
                                                strict=True)):
        cal = "not yet observable" if not np.isfinite(after) else f"{after:.3f} cm"
        out.append(f"    beacon {k} at ({pos[0]:.1f}, {pos[1]:.1f}): "
                   f"expected target RMSE with {k + 1} beacon(s) {cal}"
                   + (f" (without {nu} errors {plain:.3f} cm)" if nu else ""))
    return out


def track_table(report: TrackReport) -> str:
    """The track step by step, then its final estimate."""
    rows = [("step", "beacon (true)", "seen", "yaw err °", "offset err cm", "target err cm",
             "spread yaw °", "spread cm")]
    for s in report.steps:
        rows.append((str(s.step), f"({s.beacon_position[0]:.2f}, {s.beacon_position[1]:.2f})",
                     "yes" if s.seen else "no", f"{s.mirror_yaw_error_deg:.3f}",
                     f"{s.mirror_offset_error_cm:.3f}", f"{s.target_error_cm:.2f}",
                     f"{s.yaw_spread_deg:.3f}", f"{s.offset_spread_cm:.3f}"))
    f = report.final
    seen = sum(s.seen for s in report.steps)
    return "\n".join([f"{report.scene}: {report.path} path (heading {report.heading}), "
                      f"{len(report.steps)} poses "
                      f"({seen} seen), odometry σ {report.odometry_sigma:g} cm"
                      + (f"; {len(report.fixed)} fixed beacon(s) beside it" if report.fixed
                         else ""), *columns(rows),
                      f"final: target ({f.target[0]:.2f}, {f.target[1]:.2f}), error "
                      f"{f.target_error_cm:.2f} cm; mirror yaw error "
                      f"{f.mirror_yaw_error_deg:.3f}°, offset error "
                      f"{f.mirror_offset_error_cm:.3f} cm"])


def _dof(nu: float) -> str:
    """A degrees-of-freedom figure (∞: a Gaussian's; from 1000 on, as good as one)."""
    return "∞" if nu >= 1e3 else f"{nu:.2g}"


def error_model_summary(model: ErrorModel) -> str:
    """The model in a few printed lines (σ_d in %)."""
    lines = [f"error model ({model.kind} bench): σ = exp(w·z), the scale of a Student-t of "
             "ν degrees of freedom, z = [1, " + ", ".join(SIGMA_FEATURES) + "] standardized; "
             f"α (and a 3-D model's elevation) in degrees at fx "
             f"{model.fx_px or float('nan'):.0f} px, d_total in % of "
             "d_total; 95 % of the rows' errors within 1.96·tail σ"]
    for kind, qs in model.fits.items():
        for q, m in qs.items():
            scale, unit = (100.0, " %") if q == "d_rel" else (1.0, "°")
            w = ", ".join(f"{n} {c:+.3f}" for n, c in zip(SIGMA_FEATURES, m.log_sigma.weights,
                                                          strict=True))
            lines.append(f"  {kind:6s} {q:5s}: n={m.n} ({m.gross_errors} gross left out of "
                         f"the law), RMS own error {scale * m.rms:.4f}{unit}, typical σ "
                         f"{scale * m.typical_sigma:.4f}{unit}, ν {_dof(m.dof)}, tail "
                         f"×{m.tail:.2f}; log σ "
                         f"slopes: {w}")
    lines.append(f"  an α offset shared by every image of a frame beyond the tolerances: σ "
                 f"{model.shared_alpha_deg:.4f}°" + (
                     " (each α law above is the image's own part)" if model.shared_alpha_deg
                     else " (none found)"))
    lines.append(tail_line(model.tail))
    if model.three_d:
        lines.append(f"  a 3-D model: its 3-D solves' covariance widened ×"
                     f"{model.ellipsoid_scale:.2f} (95 % of its rows' truths in their 95 % "
                     "ellipsoid)")
    t = model.tolerances
    if not t.ideal:
        lines.append(f"  its benches' shared errors (half-widths), estimated with priors: pan "
                     f"±{t.pan_deg:g}°, calibration distance ±{t.calibration_cm:g} cm, "
                     f"curvature ±{t.curvature_per_cm:.3g}/cm, beacon positions "
                     f"±{t.beacon_position_cm:g} cm")
    for kind, feats in model.domain.features.items():
        lines.append(f"  domain, {kind}: " + ", ".join(
            f"{n} {lo:.3g}–{hi:.3g}" for n, (lo, hi) in feats.items()))
    lines.append("  domain, scenes: " + ", ".join(
        f"{n} {lo:.3g}–{hi:.3g}" for n, (lo, hi) in model.domain.scene.items()))
    for note in (model.provenance or {}).get("warnings", []):
        lines.append(f"  warning: a loosely determined law: {note}")
    return "\n".join(lines)


def tail_line(tail: Tail) -> str:
    """How an error model's ellipses are drawn, in words."""
    if tail.gaussian:
        return ("  the target's distance from an estimate taken as Gaussian: its 95 % ellipse "
                "at 2.45 σ")
    # what the fit says of the σ's: heavier tails than a Gaussian's, or σ's wider or
    # narrower than the errors they were fitted to (a bench model's priors, say)
    why = ("the detector's errors are heavier-tailed" if tail.dof < HEAVY_DOF else
           "the errors are larger than the σ's say" if tail.scale > 1 else
           "the errors are smaller than the σ's say" if tail.scale < 1 else "")
    return (f"  the target's distance from an estimate, fitted on these rows solved again: a "
            f"2-D Student-t of scale {tail.scale:.3f} and {tail.dof:.3g} degrees of freedom "
            f"(median {tail.radius(0.5):.2f} σ): its 95 % ellipse at "
            f"{tail.radius(0.95):.2f} σ" + (f", not a Gaussian's 2.45 ({why})" if why else
                                            ", as a Gaussian's"))


# degrees of freedom below which a tail is said heavier than a Gaussian's (at 30 its
# 95 % radius is 5 % beyond a Gaussian's)
HEAVY_DOF = 30.0
