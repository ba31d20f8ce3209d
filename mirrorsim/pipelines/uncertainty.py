"""Whether an error model's error bars hold on rows it was not fitted on.

Each held-out dataset row's measurements (what the solver saw: the observer, the
beacon's believed position, the measured α and d_total) are solved again with the σ's
the model gives them, and the estimate's covariance is held against the true target:

* the coverage of the target's 50, 90 and 95 % ellipses (drawn at the radii of the
  model's tail, :class:`~solver.measurements.Tail`), with a Clopper–Pearson 95 %
  interval (a model is honest where the interval holds the nominal level);
* the median Mahalanobis distance, against its tail's median and χ₂'s, √(2 ln 2) = 1.18;
* for each measurement (target and beacon, α and d_total), the fraction of errors within
  1σ and 2σ, against what its law's Student-t of ν degrees of freedom puts there (0.683
  and 0.954 for a Gaussian's);
* a reliability diagram: nominal against empirical coverage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.error_model import KINDS, ErrorModel, ImageFeatures
from mirrorsim.formats.files import save_figure
from mirrorsim.pipelines.error_features import model_own_errors, sigma_features_of
from mirrorsim.pipelines.solving import model_calibration
from solver.errors import SolverError
from solver.lsq import solve_measurements
from solver.measurements import GAUSSIAN, BeaconMeasurement, Tail
from solver.selfcal import SelfCalibration, parse_priors

LEVELS = (0.5, 0.9, 0.95)
CHI2_MEDIAN = math.sqrt(2.0 * math.log(2.0))  # the median of a χ with 2 degrees of freedom


def binomial_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Clopper–Pearson interval of a proportion k/n."""
    from scipy.stats import beta

    a = (1.0 - confidence) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


@dataclass(frozen=True)
class Coverage:
    """How many held-out targets fell inside the ``level`` ellipse."""

    level: float
    inside: int
    n: int

    @property
    def fraction(self) -> float:
        """The fraction inside."""
        return self.inside / self.n if self.n else math.nan

    def to_json(self) -> dict:
        """The validation file's entry."""
        lo, hi = binomial_interval(self.inside, self.n)
        return {"level": self.level, "inside": self.inside, "n": self.n,
                "fraction": self.fraction, "interval95": [lo, hi]}


@dataclass(frozen=True)
class Validation:
    """An error model held against held-out rows."""

    n_rows: int  # the held-out rows whose scene did not fail
    n_failed: int  # of those, the ones the solver could not solve again
    mahalanobis: np.ndarray  # per solved row
    coverage: tuple[Coverage, ...]
    within: dict[str, dict[str, tuple[float, float]]]  # kind → quantity → (1σ, 2σ)
    # kind → quantity → what its law's t_ν puts within 1σ and 2σ
    expected: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)
    n_scene_failed: int = 0  # rows whose scene had failed in the dataset (not attempted)
    tail: Tail = GAUSSIAN  # the model's: where each level's ellipse is drawn

    @property
    def median_mahalanobis(self) -> float:
        """The median distance in σ's (the tail's median for an honest model: 1.18 for
        Gaussian ellipses)."""
        return float(np.median(self.mahalanobis)) if self.mahalanobis.size else math.nan

    def to_json(self) -> dict:
        """The validation document."""
        return {"rows": self.n_rows, "not_solved": self.n_failed,
                "scenes_failed": self.n_scene_failed,
                "coverage": [c.to_json() for c in self.coverage],
                "median_mahalanobis": self.median_mahalanobis,
                "chi2_2_median": CHI2_MEDIAN, "tail": self.tail.to_json(),
                "tail_median": self.tail.radius(0.5),
                "within": {k: {q: {"1sigma": a, "2sigma": b} for q, (a, b) in qs.items()}
                           for k, qs in self.within.items()},
                "expected_within": {k: {q: {"1sigma": a, "2sigma": b}
                                        for q, (a, b) in qs.items()}
                                    for k, qs in self.expected.items()}}


def _col(cols: dict, name: str) -> np.ndarray:
    if name not in cols:
        raise ValueError(f"the dataset has no column {name!r}: it was made by an older "
                         "mirrorsim; make it again")
    return np.asarray(cols[name], float)


def validate(model: ErrorModel, cols: dict) -> Validation:
    """Solve each usable row of ``cols`` (dataset columns) again with ``model``'s σ's and
    score the target's covariance against the true target (planar rows only:
    :func:`~mirrorsim.formats.dataset_table.require_planar`)."""
    table.require_planar(cols)
    n = len(cols["index"])
    ok = table.usable_rows(cols)
    pan = _col(cols, "observer_pan_deg")
    fx = table.focal_lengths(cols)
    obs = np.column_stack([_col(cols, "observer_x"), _col(cols, "observer_y")])
    truth = np.column_stack([_col(cols, "target_x"), _col(cols, "target_y")])
    target = np.column_stack([_col(cols, "target_alpha_meas"), _col(cols, "target_d_meas")])
    # each scene's beacons as its row has them, solved as the dataset solved them
    images, _, scene_of = table.image_rows(cols)
    beacon = np.column_stack([_col(images, f"beacon_{q}") for q in
                              ("known_x", "known_y", "alpha_meas", "d_meas")])
    calibrate = cols.get("calibrate") or [""] * n
    beacon_sigma = cols.get("beacon_sigma") or [0.0] * n
    priors = cols.get("calibrate_priors") or [""] * n
    t_feat = image_features_of(cols, "target")
    b_feat = image_features_of(images, "beacon")
    dist, failed = [], 0
    for i in np.flatnonzero(ok):
        t = tuple(target[i])
        # image_rows gives a scene's beacons in their order
        beacons = [BeaconMeasurement((x, y), a, d) for x, y, a, d in beacon[scene_of == i]]
        try:
            asked = SelfCalibration(tuple(x for x in (calibrate[i] or "").split(",") if x),
                                    float(beacon_sigma[i] or 0.0), parse_priors(priors[i] or ""))
            # as evaluate solves with this model: its bench's shared errors besides
            calibration = model_calibration(model, asked)
            sigma = model.sigmas(t_feat[i], [b_feat[j] for j in np.flatnonzero(scene_of == i)],
                                 pan[i], fx_px=fx[i] if np.isfinite(fx[i]) else None)
            sol = solve_measurements(obs[i], beacons, [t], sigma=sigma, calibration=calibration)
            dist.append(sol.mahalanobis(truth[i]))
        except (SolverError, np.linalg.LinAlgError):
            failed += 1
    m = np.asarray(dist, float)
    coverage = tuple(Coverage(p, int(np.sum(m <= model.tail.radius(p))), len(m))
                     for p in LEVELS)
    return Validation(int(ok.sum()), failed, m, coverage, _within(model, cols, ok),
                      _expected_within(model), int((~ok).sum()), model.tail)


def _expected_within(model: ErrorModel) -> dict[str, dict[str, tuple[float, float]]]:
    """What each quantity's Student-t of its fitted ν puts within 1σ and 2σ of its scale
    (0.683 and 0.954 for a Gaussian's, ν infinite)."""
    from scipy.stats import t as student  # (ν = ∞: the normal's)

    return {kind: {q: tuple(float(2.0 * student.cdf(k, f.dof) - 1.0) for k in (1.0, 2.0))
                   for q, f in qs.items()}
            for kind, qs in model.fits.items()}


def image_features_of(cols: dict, kind: str) -> list[ImageFeatures]:
    """Each row's ``kind`` image as the error model weighs it, from its columns."""
    c = lambda name: _col(cols, table.object_column(kind, name))  # noqa: E731
    return [ImageFeatures(*row) for row in zip(
        c("alpha_meas"), c("d_meas"), c("height_px_meas"), c("contrast"), c("noise"),
        np.nan_to_num(c("jpeg_quality")).astype(int), strict=True)]


def _within(model: ErrorModel, cols: dict, ok: np.ndarray
            ) -> dict[str, dict[str, tuple[float, float]]]:
    """Each measurement's own errors (the frame's shared parts apart) in the model's
    σ's: the fractions within 1σ and 2σ."""
    out: dict[str, dict[str, tuple[float, float]]] = {}
    cols, beacon_of, scene_of = table.image_rows(cols)  # every beacon's image, the target once
    ok = ok[scene_of]
    once = table.counted_once(beacon_of)
    for kind in KINDS:
        x = sigma_features_of(cols, kind)
        out[kind] = {}
        for q in ("alpha", "d_rel"):
            err = model_own_errors(cols, model, kind, q=q)
            m = ok & once[kind] & np.isfinite(err) & np.isfinite(x).all(axis=1)
            z = np.abs(err[m]) / model.whole_sigma(kind, q, x[m], fx_px=model.fx_px)
            out[kind][q] = (float(np.mean(z <= 1.0)), float(np.mean(z <= 2.0))) if z.size \
                else (math.nan, math.nan)
    return out


def report_lines(v: Validation) -> list[str]:
    """The validation as printed lines (σ fractions against their laws' t_ν values)."""
    lines = [f"held-out rows: {v.n_rows} ({v.n_failed} not solved again; "
             f"{v.n_scene_failed} whose scene had failed, left out)"]
    for c in v.coverage:
        lo, hi = binomial_interval(c.inside, c.n)
        lines.append(f"  {100 * c.level:.0f} % ellipse: {c.inside}/{c.n} inside = "
                     f"{c.fraction:.3f} (95 % interval {lo:.3f}–{hi:.3f})")
    lines.append(f"  median Mahalanobis distance {v.median_mahalanobis:.2f} (honest: "
                 + (f"{CHI2_MEDIAN:.2f})" if v.tail.gaussian else
                    f"{v.tail.radius(0.5):.2f} by the model's tail, {CHI2_MEDIAN:.2f} for "
                    "Gaussian errors)"))
    for kind, qs in v.within.items():
        for q, (a, b) in qs.items():
            e1, e2 = v.expected[kind][q]
            lines.append(f"  {kind:6s} {q:5s} errors within 1σ {a:.3f} ({e1:.3f}), within "
                         f"2σ {b:.3f} ({e2:.3f})")
    return lines


def reliability_plot(v: Validation, out: str | Path, title: str = "") -> Path:
    """Nominal against empirical coverage of the target's ellipses (with each level's
    Clopper–Pearson interval), and the Mahalanobis distances against χ₂."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    levels = np.linspace(0.05, 0.99, 40)
    m = v.mahalanobis
    inside = np.array([np.sum(m <= v.tail.radius(p)) for p in levels])
    band = np.array([binomial_interval(int(round(p * m.size)), m.size) for p in levels])
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 5))
    a.plot([0, 1], [0, 1], "k--", lw=1, label="honest")
    a.fill_between(levels, band[:, 0], band[:, 1], color="0.85",
                   label="95 % binomial band of an honest model")
    a.plot(levels, inside / max(m.size, 1), "o-", ms=3, color="#c0392b",
           label=f"held-out rows (n = {m.size})")
    a.set_xlabel("nominal coverage of the target's ellipse")
    a.set_ylabel("fraction of true targets inside")
    a.set_title("reliability")
    a.legend(fontsize=8)
    r = np.linspace(0, max(4.0, float(np.percentile(m, 99)) if m.size else 4.0), 200)
    b.hist(m, bins=30, range=(0, r[-1]), density=True, color="#c0392b", alpha=0.6,
           label="held-out rows")
    b.plot(r, GAUSSIAN.density(r), "k--", lw=1, label="χ with 2 degrees of freedom")
    if not v.tail.gaussian:
        b.plot(r, v.tail.density(r), "k:", lw=1.5,
               label=f"the model's tail (scale {v.tail.scale:.2f}, ν {v.tail.dof:.2f})")
    b.axvline(v.median_mahalanobis, color="#c0392b", lw=1,
              label=f"median {v.median_mahalanobis:.2f} (honest {v.tail.radius(0.5):.2f})")
    b.set_xlabel("Mahalanobis distance of the true target (σ's)")
    b.set_ylabel("density")
    b.legend(fontsize=8)
    fig.suptitle(title or "error model on held-out rows")
    return save_figure(fig, out)
