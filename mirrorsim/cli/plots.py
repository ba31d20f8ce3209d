"""The pictures of the commands (evaluation, plan, budget, track), drawn with matplotlib;
the top view they draw on is :mod:`mirrorsim.cli.top_view`'s."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")  # files only; no display on the machines this runs on
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mirrorsim.cli.top_view import draw_top_view, legend_below  # noqa: E402
from mirrorsim.formats.files import atomic_path, save_figure  # noqa: E402
from mirrorsim.pipelines.score import Report  # noqa: E402
from mirrorsim.scene.model import Scene  # noqa: E402
from solver.geometry import unit  # noqa: E402

if TYPE_CHECKING:  # the budget and the track run renders: no Mitsuba import to draw one
    from mirrorsim.formats.error_model import ErrorModel
    from mirrorsim.pipelines.budget import Budget
    from mirrorsim.pipelines.planning import Plan
    from mirrorsim.pipelines.track_report import TrackReport


def _save(fig, out: Path, dpi: int) -> Path:
    return save_figure(fig, out, dpi)


def plot_evaluation(scene: Scene, report: Report, out: str | Path, *, dpi: int = 130) -> Path:
    """Truth against estimate (like the paper's Figs. 7 and 11): the top view with the
    estimated mirror line and target, and a close-up of the target with the solver's
    95 % error ellipse."""
    from matplotlib.patches import Ellipse

    fig, (ax, zoom) = plt.subplots(1, 2, figsize=(14, 7))
    draw_top_view(ax, scene)
    sol, err = report.solution, report.errors
    p = np.asarray(sol.mirror.point, float)
    d = unit(sol.mirror.yaw_deg) * 2 * scene.mirror.size[0]
    est = np.asarray(sol.target, float)
    truth = np.asarray(scene.target.position, float)
    for a in (ax, zoom):
        a.plot(*zip(p - d, p + d, strict=True), color="#d62728", ls="--", lw=1.2,
               label=f"estimated mirror (yaw error {err.mirror_yaw_deg:.3f}°)")
        a.plot(*est, "x", color="#d62728", ms=10, mew=2,
               label=f"estimated target (error {err.target_cm:.3f} cm)")
    legend_below(ax)
    ellipse = sol.ellipse95()
    half = max(1.0, 2.5 * err.target_cm)
    if ellipse is not None:
        major, minor, angle = ellipse
        zoom.add_patch(Ellipse(est, 2 * major, 2 * minor, angle=angle, fill=False,
                               color="#d62728", lw=1.2, label="95 % error ellipse"))
        half = max(half, 1.3 * major)
    zoom.plot(*truth, "*", color="#c0392b", ms=16, mec="k", label="true target")
    if ellipse is not None and ellipse[0] < half / TOO_SMALL:  # a dot at this scale
        _ellipse_inset(zoom, est, truth, ellipse)
    t0, t1 = scene.target.ends()
    zoom.plot(*zip(t0, t1, strict=True), color="#c0392b", lw=3, alpha=0.4)
    zoom.set_xlim(truth[0] - half, truth[0] + half)
    zoom.set_ylim(truth[1] - half, truth[1] + half)
    zoom.set_aspect("equal")
    zoom.grid(alpha=0.3)
    zoom.legend(loc="upper left", fontsize=8)
    zoom.set_title("the target: truth, estimate and the solver's 95 % ellipse")
    return _save(fig, Path(out), dpi)


# an ellipse whose semi-major axis is less than the close-up's half-width over this is
# a dot there (0.08 cm in a 2.5 cm view): it gets an inset of its own scale
TOO_SMALL = 15.0


def _ellipse_inset(zoom, est: np.ndarray, truth: np.ndarray,
                   ellipse: tuple[float, float, float]) -> None:
    """An inset in the close-up's lower right at the ellipse's own scale: the estimate,
    the ellipse and (where it falls inside) the truth."""
    from matplotlib.patches import Ellipse

    major, minor, angle = ellipse
    inset = zoom.inset_axes([0.58, 0.03, 0.4, 0.4])
    inset.add_patch(Ellipse(est, 2 * major, 2 * minor, angle=angle, fill=False,
                            color="#d62728", lw=1.2))
    inset.plot(*est, "x", color="#d62728", ms=8, mew=2)
    inset.plot(*truth, "*", color="#c0392b", ms=12, mec="k")
    r = 1.6 * major
    inset.set_xlim(est[0] - r, est[0] + r)
    inset.set_ylim(est[1] - r, est[1] + r)
    inset.set_aspect("equal")
    inset.tick_params(labelsize=6)
    inset.set_title(f"95 % ellipse, {major:.3g} × {minor:.3g} cm", fontsize=7)
    zoom.indicate_inset_zoom(inset, edgecolor="0.4")


def plot_plan(scene: Scene, plan: Plan, out: str | Path, *, dpi: int = 130) -> Path:
    """The placement analysis in four panels (like the paper's Figs. 4–6): the paper's
    triangle and the exact region where a beacon is seen for every mirror orientation
    within ±ε; the three moving-beacon paths; the expected target error over the board
    with the best position; the beacon area against d_total (paper vs exact)."""
    out = Path(out)
    fig, axes = plt.subplots(2, 2, figsize=(12, 11))
    _plan_region(axes[0, 0], scene, plan)
    _plan_paths(axes[0, 1], plan)
    _plan_error_map(fig, axes[1, 0], scene, plan)
    _plan_areas(axes[1, 1], plan)
    fig.suptitle(f"{scene.name}: beacon placement", fontsize=11)
    return _save(fig, out, dpi)

def _plan_region(ax, scene: Scene, plan: Plan) -> None:
    geo, alpha = plan.geometry, plan.target_alpha_deg
    R = np.asarray(geo.R) + np.asarray(scene.camera.position, float)
    reg = plan.region
    ax.contourf(reg.xs, reg.ys, reg.mask.astype(float), levels=[0.5, 1.5],
                colors=["#9ecae1"], alpha=0.7)
    for side in (1, -1):
        tri = geo.triangle(alpha, side) + np.asarray(scene.camera.position, float)
        ax.fill(tri[:, 0], tri[:, 1], facecolor="#fdae6b", edgecolor="#e6550d", alpha=0.8,
                label="paper's triangle (a/2 × b)" if side == 1 else None)
    c = np.asarray(scene.camera.position, float)
    ax.plot(*zip(c, c + 1.2 * plan.target_d_total * unit(alpha), strict=True), "k:", lw=0.8)
    half = unit(alpha + 90.0) * scene.mirror.size[0] / 2
    ax.plot(*zip(R - half, R + half, strict=True), color="#2a7fbf", lw=3,
            label="mirror at R = d_total along α, square-on (±ε)")
    ax.plot(*R, "k+", ms=12)
    ax.set_title(f"where a beacon is seen for every mirror orientation within ±{plan.eps_deg:g}°"
                 "\n(blue: exact; orange: the paper's triangle)", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    ax.legend(fontsize=7, loc="upper left")
    zoom = 1.6 * scene.mirror.size[0]
    ax.set_xlim(R[0] - zoom, R[0] + zoom)
    ax.set_ylim(R[1] - zoom, R[1] + zoom)


def _plan_paths(ax, plan: Plan) -> None:
    geo = plan.geometry
    colours = {"linear": "green", "rectangular": "orange", "sawtooth": "blue"}
    for k, (kind, pts) in enumerate(plan.paths.items()):
        shift = np.array([k * (geo.half_a * 2.6), 0.0])
        ax.plot(pts[:, 0] + shift[0], pts[:, 1], "-o", ms=2, color=colours[kind],
                label=f"{kind}: {plan.path_lengths[kind]:.1f} cm")
    ax.set_aspect("equal")
    ax.set_xlabel("along the path's side steps (cm; paths drawn apart)")
    ax.set_ylabel("along the path (cm)")
    ax.set_title(f"moving-beacon paths (eqs 19–21), {plan.n_steps} steps of b = "
                 f"{geo.b:.2f} cm, a = {2 * geo.half_a:.2f} cm", fontsize=9)
    ax.legend(fontsize=7)


def _plan_error_map(fig, ax, scene: Scene, plan: Plan) -> None:
    best = plan.best
    err = np.where(np.isfinite(best.map), best.map, np.nan)
    from matplotlib.colors import LogNorm

    low = max(np.nanmin(err), 1e-3)
    im = ax.pcolormesh(best.xs, best.ys, err, cmap="viridis_r", shading="auto",
                       norm=LogNorm(vmin=low, vmax=100 * low))
    cb = fig.colorbar(im, ax=ax, shrink=0.8)
    cb.set_label("expected target RMSE of a beacon there alone (cm, log scale)")
    for o in scene.occluders:
        ax.plot(*zip(o.start, o.end, strict=True), color="#555", lw=4)
    m0, m1 = scene.mirror.ends()
    ax.plot(*zip(m0, m1, strict=True), color="#2a7fbf", lw=3)
    ax.plot(*scene.target.position, "r*", ms=12, mec="k", label="target")
    for i, (b, (e, _)) in enumerate(zip(scene.beacons, plan.scene_beacons, strict=True)):
        ax.plot(*b.position, "o", color="#d4a017", mec="k",
                label=f"scene beacon {i} alone: {e:.2f} cm")
    ax.plot(*best.position, "wP", ms=12, mec="k", label=f"best single: {best.rmse:.2f} cm")
    if plan.beacon_set is not None:
        bs = plan.beacon_set
        ax.plot(*bs.positions.T, "s", color="w", mec="k", ms=7,
                label=f"{len(bs.positions)} planned: {bs.rmse[-1]:.2f} cm"
                + (f" ({'+'.join(bs.calibration.nuisances)} estimated)"
                   if bs.calibration.nuisances else ""))
        for k, p in enumerate(bs.positions):
            ax.annotate(str(k), p, xytext=(4, 4), textcoords="offset points", fontsize=8,
                        color="k", weight="bold",
                        bbox={"boxstyle": "round,pad=0.15", "fc": "w", "ec": "none"})
    ax.set_xlim(0, scene.board.size[0])
    ax.set_ylim(0, scene.board.size[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(f"expected target error over {plan.n_poses} mirror poses\n"
                 f"{plan.sigma.describe()}", fontsize=9)


def _plan_areas(ax, plan: Plan) -> None:
    ds, lit, exact = plan.area_vs_d
    ax.plot(ds, lit, "o-", color="#e6550d", label="paper's triangle (eqs 14, 18)")
    ax.plot(ds, exact, "s-", color="#3182bd", label="exact region (numerical)")
    ax.set_xlabel("d_total (cm)")
    ax.set_ylabel("area (cm²)")
    ax.set_yscale("log")
    ax.set_title("Section 7's claim: the area does not depend on d_total", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)



def plot_budget(budget: Budget, out: str | Path, *, dpi: int = 130) -> Path:
    """Tornado chart of an error budget: how far each source alone moves the target's
    estimate from the ideal bench's (bars, largest on top) with its first-order
    prediction (ticks); the ideal bench's own error and all sources together as lines."""
    rows = sorted((c for c in budget.sources if not c.failed), key=lambda c: c.shift_cm)
    fig, ax = plt.subplots(figsize=(7.5, 1.4 + 0.45 * max(1, len(rows))))
    y = np.arange(len(rows))
    ax.barh(y, [c.shift_cm for c in rows], color="#4878a8",
            label="rendered, detected, solved")
    ax.scatter([c.predicted_shift_cm for c in rows], y, marker="|", s=300, color="#c03020",
               zorder=3, label="first-order prediction")
    ax.set_yticks(y, [c.source for c in rows])
    ax.axvline(budget.ideal_cm, color="0.4", ls=":",
               label=f"ideal bench's own error {budget.ideal_cm:.2f}")
    if budget.all is not None and not budget.all.failed:
        ax.axvline(budget.all.shift_cm, color="#c03020", ls="--",
                   label=f"all together {budget.all.shift_cm:.2f}")
    failed = [c.source for c in budget.sources if c.failed]
    ax.set_xlabel("target estimate moved from the ideal bench's (cm)"
                  + (f"\nno estimate (frames refused): {', '.join(failed)}" if failed else ""))
    ax.set_title(f"{budget.scene}: error budget of the bench")
    ax.legend(loc="lower right", fontsize=8)
    return _save(fig, Path(out), dpi)


def plot_track(report: TrackReport, out: str | Path, *, dpi: int = 120) -> Path:
    """The track's errors against the step: mirror yaw and offset with the particles'
    spread, and the target; unseen poses marked."""
    steps = np.array([s.step for s in report.steps])
    seen = np.array([s.seen for s in report.steps])
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for ax, (value, spread, label) in zip(axes, (
            ("mirror_yaw_error_deg", "yaw_spread_deg", "mirror yaw error (°)"),
            ("mirror_offset_error_cm", "offset_spread_cm", "mirror offset error (cm)"),
            ("target_error_cm", None, "target error (cm)")), strict=True):
        y = np.array([getattr(s, value) for s in report.steps])
        ax.plot(steps, y, "o-", color="#c0392b", ms=4, label="error")
        if spread:
            ax.plot(steps, [getattr(s, spread) for s in report.steps], "--", color="0.4",
                    label="particles' SD")
        if (~seen).any():
            ax.plot(steps[~seen], y[~seen], "x", color="k", ms=9, label="beacon unseen")
        ax.set_xlabel("step")
        ax.set_ylabel(label)
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(f"{report.scene}: moving beacon, {report.path} path, odometry σ "
                 f"{report.odometry_sigma:g} cm")
    return _save(fig, Path(out), dpi)


def animate_track(scene: Scene, report: TrackReport, out: str | Path, *, fps: float = 3.0
                  ) -> Path:
    """A GIF of the top view over the steps: the beacon's true and commanded positions,
    a sample of the filter's mirror lines, and the target estimate."""
    from matplotlib.animation import FuncAnimation, PillowWriter

    from solver.geometry import line_normal

    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    draw_top_view(ax, scene)
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    m = np.asarray(scene.mirror.center, float)
    half = np.array([-1.2, 1.2]) * scene.mirror.size[0]
    lines = [ax.plot([], [], color="#2e86c1", lw=0.5, alpha=0.08)[0] for _ in range(60)]
    walked, = ax.plot([], [], "-", color="#d4a017", lw=1.2, label="beacon (true)")
    told, = ax.plot([], [], ":", color="k", lw=1.0, label="beacon (commanded)")
    est, = ax.plot([], [], "*", color="#c0392b", ms=14, label="target estimate")
    title = ax.set_title("")
    ax.legend(loc="upper left", fontsize=7)

    def frame(k: int):
        s = report.steps[k]
        for line, (yaw, rho) in zip(lines, report.snapshots[k][: len(lines)], strict=False):
            n = line_normal(yaw)
            foot = n * rho + (m - n * (n @ m))  # the point of the line nearest the mirror
            d = np.array([-n[1], n[0]])
            line.set_data(*(foot[:, None] + d[:, None] * half[None]))
        upto = report.steps[: k + 1]
        walked.set_data(*np.array([u.beacon_position for u in upto]).T)
        told.set_data(*np.array([u.commanded for u in upto]).T)
        est.set_data([s.target[0]], [s.target[1]])
        title.set_text(f"step {s.step}: yaw error {s.mirror_yaw_error_deg:.2f}°, target "
                       f"error {s.target_error_cm:.2f} cm{'' if s.seen else ' (unseen)'}")
        ax.set_xlim(xlim)
        ax.set_ylim(ylim)
        return [*lines, walked, told, est, title]

    anim = FuncAnimation(fig, frame, frames=len(report.steps), blit=False)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(out) as tmp:
            anim.save(tmp, writer=PillowWriter(fps=fps), dpi=70)
    finally:
        plt.close(fig)
    return out


def plot_error_model(cols: dict, model: ErrorModel, out: str | Path) -> Path:
    """Each row's own error (the frame's shared parts apart, α at the model's focal
    length) against its image's height and off-axis bearing, with the σ the model gives
    that row (a ±2σ bar on each point), and the errors in σ's against a standard
    normal."""
    from mirrorsim.formats import dataset_table as table
    from mirrorsim.pipelines.error_features import model_own_errors, sigma_features_of

    fig, axes = plt.subplots(2, 3, figsize=(16, 8.5))
    cols, beacon_of, _ = table.image_rows(cols)  # every beacon's image; the target once
    ok = table.usable_rows(cols)
    once = table.counted_once(beacon_of)
    grid = np.linspace(-5, 5, 201)
    for r, (q, scale, units) in enumerate((("alpha", 1.0, "°"),
                                           ("d_rel", 100.0, "% of d_total"))):
        for k, (kind, colour) in enumerate((("target", "#c0392b"), ("beacon", "#b8860b"))):
            y = model_own_errors(cols, model, kind, q=q)
            S = sigma_features_of(cols, kind)
            m = ok & once[kind] & np.isfinite(y) & np.isfinite(S).all(axis=1)
            sd = model.whole_sigma(kind, q, S[m], fx_px=model.fx_px)  # y is as at its fx
            for c, (x, name) in enumerate(((np.exp(S[m, 0]), "measured image height (px)"),
                                           (S[m, 1], "|off-axis bearing| (°)"))):
                axes[r, c].errorbar(x + 0.15 * k, y[m] * scale, yerr=2 * sd * scale, fmt="o",
                                    ms=3, color=colour, ecolor=colour, elinewidth=0.6,
                                    alpha=0.6, label=f"{kind} (bar: ±2σ of the model)")
                axes[r, c].set_xlabel(name)
                axes[r, c].set_ylabel(f"{q} error ({units})")
            z = y[m] / sd
            axes[r, 2].hist(np.clip(z, -5, 5), bins=40, range=(-5, 5), density=True,
                            histtype="step", color=colour, label=f"{kind}: error / σ")
        axes[r, 2].plot(grid, np.exp(-grid**2 / 2) / np.sqrt(2 * np.pi), "k--", lw=1,
                        label="standard normal")
        axes[r, 2].set_xlabel(f"{q} error / σ (clipped to ±5)")
        axes[r, 2].set_ylabel("density")
        for ax in axes[r]:
            ax.legend(fontsize=8)
    fig.suptitle("detector errors and the error model's σ per measurement (training rows)")
    return save_figure(fig, out)
