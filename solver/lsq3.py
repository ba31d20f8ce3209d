"""3-D SLTR by weighted least squares over every beacon and every view of the target:
the mirror's plane (yaw, lean, offset) and the target in 3-D, robust to one bad image
(a Huber loss), self-calibrating for the camera's pan and pitch readings, the range
scale and the mirror's power, with priors on them; its covariance, and the Cramér–Rao
bound at the truth.

The nuisances: ``pan`` adds δ (deg) to every azimuth (the mount's pan reading),
``pitch`` adds δ to every elevation (its pitch reading: to first order, for images near
the optical axis), ``scale`` multiplies every d_total (the calibration's K), and
``power`` c = 1/R (1/cm, > 0 concave) moves each image by its own first-order amount
(:func:`~solver.sltr3d.power_terms3`, the glass curved about its images' reflection
points' middle): α + c·A, ε + c·E, s·(d + c·D).  A beacon whose position is known to
σ_p cm per axis (``position_sigma``) has its plan offset (dx, dy) estimated besides,
with a prior of σ_p on each, as the planar fit does (its height is the stand's, known).
The forward model is :mod:`solver.sltr3d`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.errors import SolverError
from solver.geometry import wrap_bearing
from solver.lsq import HUBER_K
from solver.sltr3d import (
    MirrorPlane,
    measured3,
    observe3,
    power_terms3,
    seen3,
    solve_single3,
)

# each nuisance: its neutral value
NUISANCES3 = {"pan": 0.0, "pitch": 0.0, "scale": 1.0, "power": 0.0}
Seen = tuple[float, float, float]  # what the camera sees of an image: α, ε (deg), d_total


@dataclass(frozen=True)
class Fit3:
    """A 3-D solution: the plane, the target, the nuisances' estimates, the covariance
    of (yaw [deg], lean [deg], ρ [cm], x, y, z [cm], *nuisances, *each beacon's plan
    offset where estimated) where σ's were given, and the measurements the Huber loss
    trusted less."""

    plane: MirrorPlane
    target: np.ndarray
    nuisances: dict[str, float]
    covariance: np.ndarray | None
    downweighted: tuple[str, ...] = ()

    @property
    def nuisance_sd(self) -> dict[str, float] | None:
        """Each nuisance's σ after the fit, by name (None without σ's)."""
        if self.covariance is None:
            return None
        return {n: float(np.sqrt(self.covariance[6 + i, 6 + i]))
                for i, n in enumerate(self.nuisances)}

    @property
    def target_covariance(self) -> np.ndarray | None:
        """The target's 3×3 covariance (cm²)."""
        return None if self.covariance is None else self.covariance[3:6, 3:6]

    def to_json(self) -> dict:
        """The 3-D solution document (docs/files.md): the mirror's plane n·x = offset,
        its yaw and lean, the target, its covariance (None without σ's), the nuisances
        with their σ's after the fit (None without σ's) and the measurements the robust
        fit trusted less."""
        cov = self.target_covariance
        return {"mirror": {"yaw_deg": self.plane.yaw_deg, "lean_deg": self.plane.lean_deg,
                           "normal": self.plane.normal.tolist(), "offset_cm": self.plane.rho},
                "target": self.target.tolist(),
                "target_covariance": None if cov is None else cov.tolist(),
                "nuisances": dict(self.nuisances), "nuisance_sd": self.nuisance_sd,
                "downweighted": list(self.downweighted)}


@dataclass(frozen=True)
class Measurements3:
    """What the experimenter measured in 3-D (docs/files.md's 3-D measurements): the
    lens's position, each beacon's believed base with its image's (α, ε, d_total), the
    target's; optionally the heights measured (each beacon's, then the target's: the
    readings are then modelled as a detector's, :func:`~solver.sltr3d.measured3`), how
    far before each axis the measured face stands, each observation's σ's (α deg,
    ε deg, d_total relative; the beacons', then the target's) and the camera's pan."""

    observer: tuple[float, float, float]
    beacons: tuple[tuple[tuple[float, float, float], Seen], ...]
    target: Seen
    heights: tuple[float, ...] | None = None
    fronts: tuple[float, ...] | None = None
    sigma: tuple[tuple[float, float, float], ...] | None = None
    pan_deg: float | None = None  # the camera's pan as its mount reports it

    def to_json(self) -> dict:
        """The 3-D measurements document."""
        def image(s: Seen) -> dict:
            return {"alpha_deg": s[0], "elevation_deg": s[1], "d_total": s[2]}

        out = {"observer": list(self.observer), "target": image(self.target),
               "beacons": [{"position": list(p), **image(s)} for p, s in self.beacons]}
        if self.heights is not None:
            out["heights"] = list(self.heights)
        if self.fronts is not None:
            out["fronts"] = list(self.fronts)
        if self.sigma is not None:
            out["sigma"] = [{"alpha_deg": a, "elevation_deg": e, "d_total_rel": d}
                            for a, e, d in self.sigma]
        if self.pan_deg is not None:
            out["observer_pan_deg"] = self.pan_deg
        return out

    def solve(self, *, nuisances: tuple[str, ...] = (),
              priors: dict[str, float] | None = None, position_sigma: float = 0.0) -> Fit3:
        """:func:`solve_lsq3` of these measurements."""
        return solve_lsq3(self.observer, list(self.beacons), [self.target],
                          sigma=None if self.sigma is None else np.array(self.sigma),
                          heights=self.heights, fronts=self.fronts, pan_deg=self.pan_deg,
                          nuisances=nuisances, priors=priors, position_sigma=position_sigma)


@dataclass(frozen=True)
class _Problem:
    """What the fit weighs: the observer, the beacons' positions, what was seen (beacons
    first), the σ's, the nuisances and their priors, and the normal's side."""

    o: np.ndarray
    positions: list[np.ndarray]
    seen: np.ndarray
    sigma: tuple[float, float, float] | np.ndarray  # one triple, or a row per observation
    nuisances: tuple[str, ...]
    priors: dict[str, float]
    flip: bool
    heights: tuple[float, ...] | None = None  # each object's (beacons', then the target's)
    fronts: tuple[float, ...] | None = None  # each measured face's offset (likewise)
    pan_deg: float | None = None  # the camera's pan, where the readings are a detector's
    position_sigma: float = 0.0  # each beacon's plan position known to this (cm per axis)

    def offsets(self, x: np.ndarray) -> np.ndarray:
        """Each beacon's estimated plan offset (zero unless ``position_sigma``)."""
        k = 6 + len(self.nuisances)
        if not self.position_sigma:
            return np.zeros((len(self.positions), 2))
        return x[k:k + 2 * len(self.positions)].reshape(-1, 2)

    def predicted(self, x: np.ndarray) -> np.ndarray:
        """(α, ε, d_total) of every observation at parameters ``x``: of each object's
        base (:func:`~solver.sltr3d.seen3`), or with ``heights`` as a detector reads
        its image (:func:`~solver.sltr3d.measured3`)."""
        plane = MirrorPlane.from_params(x[0], x[1], x[2], flip=self.flip)
        n_b = len(self.positions)
        positions = [p + np.r_[d, 0.0] for p, d in zip(self.positions, self.offsets(x),
                                                       strict=True)]

        def image(p: np.ndarray, k: int) -> tuple[float, float, float]:  # object k's
            if self.heights is None:
                return seen3(self.o, plane, p)
            return measured3(self.o, plane, p, height=self.heights[k],
                             front=self.fronts[k] if self.fronts else 0.0, pan_deg=self.pan_deg)

        pr = np.array([image(p, k) for k, p in enumerate(positions)]
                      + [image(x[3:6], n_b)] * (len(self.seen) - n_b))
        v = dict(zip(self.nuisances, x[6:6 + len(self.nuisances)], strict=True))
        if "power" in v:  # the glass curved about its images' middle: d = s·(d + c·D)
            terms = power_terms3(self.o, plane, [*positions, x[3:6]])
            pr += v["power"] * np.vstack([terms, np.repeat(terms[-1:], len(pr) - n_b - 1, 0)])
        pr[:, 0] += v.get("pan", 0.0)
        pr[:, 1] += v.get("pitch", 0.0)
        pr[:, 2] *= v.get("scale", 1.0)
        return pr

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """The weighted residuals at ``x`` against the measurements, then each prior's
        row."""
        seen = self.seen
        pr = self.predicted(x)
        sa, se, sd = np.broadcast_to(np.asarray(self.sigma, float), seen.shape).T
        da = wrap_bearing(pr[:, 0] - seen[:, 0])
        rows = [da / sa, (pr[:, 1] - seen[:, 1]) / se, (pr[:, 2] - seen[:, 2]) / (sd * seen[:, 2])]
        rows.append(np.array([(v - NUISANCES3[n]) / self.priors[n]
                              for n, v in zip(self.nuisances, x[6:6 + len(self.nuisances)],
                                              strict=True)
                              if n in self.priors]))
        if self.position_sigma:
            rows.append(self.offsets(x).ravel() / self.position_sigma)
        return np.concatenate(rows)

    def names(self) -> list[str]:
        """What each residual measures, in their order."""
        who = [f"beacon {i}" for i in range(len(self.positions))] + [
            f"target {k}" for k in range(len(self.seen) - len(self.positions))]
        return ([f"{w} α" for w in who] + [f"{w} elevation" for w in who]
                + [f"{w} d_total" for w in who]
                + [f"the {n} prior" for n in self.nuisances if n in self.priors]
                + ([f"beacon {i} position {a} prior" for i in range(len(self.positions))
                    for a in "xy"] if self.position_sigma else []))

    def start(self, x: np.ndarray) -> np.ndarray:
        """``x`` (the plane, the target) with each nuisance at its neutral value, and
        each beacon's offset at 0 where estimated."""
        return np.array([*x, *(NUISANCES3[n] for n in self.nuisances),
                         *([0.0] * (2 * len(self.positions) if self.position_sigma else 0))])


def solve_lsq3(observer: ArrayLike, beacons: list[tuple[ArrayLike, Seen]], targets: list[Seen],
               *, sigma: tuple[float, float, float] | np.ndarray | None = None,
               nuisances: tuple[str, ...] = (), priors: dict[str, float] | None = None,
               heights: tuple[float, ...] | None = None, fronts: tuple[float, ...] | None = None,
               pan_deg: float | None = None, position_sigma: float = 0.0) -> Fit3:
    """The mirror's plane and the target from every beacon (its position, and what the
    camera saw of it: α, ε, d_total) and every view of the target, by weighted least
    squares from the first beacon's closed form.  ``sigma``: (σ_α deg, σ_ε deg, σ_d as a
    fraction of d_total) of every measurement, or a row per observation (the beacons',
    then the target's); without it, weights of (0.01°, 0.01°, 0.2 %) and no covariance.
    ``nuisances``: any of ``pan``, ``pitch``, ``scale``, ``power``, estimated alongside;
    ``priors``: the σ of each one known (deg; the scale's a fraction; the power's 1/cm).
    ``heights``, ``fronts``, ``pan_deg``: each beacon's and the target's measured height
    and face offset (cm) and the camera's pan, to predict each reading as a detector
    makes it (:func:`~solver.sltr3d.measured3`: a leaning mirror's bias removed);
    without them as each base's exact image.  ``position_sigma``: each beacon's plan
    position known to this (cm per axis), its offset estimated with that prior.

    Raises
    ------
    SolverError
        No beacon or target, an unknown nuisance, or a geometry that does not determine
        the unknowns.
    """
    from scipy.optimize import least_squares  # scipy is slow to import: only when used

    if not beacons or not targets:
        raise SolverError("least squares needs at least one beacon and one target observation")
    unknown = [n for n in (*nuisances, *(priors or {})) if n not in NUISANCES3]
    if unknown or set(priors or {}) - set(nuisances):
        raise SolverError(f"nuisances are {', '.join(NUISANCES3)}, each prior on one of them")
    _check_objects(len(beacons), heights, fronts)
    o = np.asarray(observer, float)
    start = solve_single3(o, beacons[0][0], beacons[0][1], target_seen=targets[0])
    p = _Problem(o, [np.asarray(b, float) for b, _ in beacons],
                 np.array([s for _, s in beacons] + list(targets), float),
                 (0.01, 0.01, 0.002) if sigma is None else np.asarray(sigma, float),
                 tuple(nuisances), dict(priors or {}),
                 flip=start.plane.flip, heights=None if heights is None else tuple(heights),
                 fronts=None if fronts is None else tuple(fronts), pan_deg=pan_deg,
                 position_sigma=position_sigma)
    x0 = p.start([start.plane.yaw_deg, start.plane.lean_deg, start.plane.rho, *start.target])
    if len(p.residuals(x0)) < len(x0):  # (each prior brings its own row)
        raise SolverError(f"{len(x0)} unknowns from {len(p.residuals(x0))} measurements")
    robust = len(p.residuals(x0)) > len(x0)
    res = least_squares(p.residuals, x0, method="trf" if robust else "lm",
                        loss="huber" if robust else "linear", f_scale=HUBER_K,
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    r = p.residuals(res.x)
    w = np.where(np.abs(r) > HUBER_K, HUBER_K / np.maximum(np.abs(r), 1e-300), 1.0)
    J = _jacobian(p, res.x)
    jtj = J.T @ (w[:, None] * J)
    if np.linalg.cond(jtj) > 1e14:
        raise SolverError("the beacons and the target do not determine the mirror's plane"
                          + (" and the nuisances" if nuisances else ""))
    names, plane = p.names(), MirrorPlane.from_params(*res.x[:3], flip=p.flip)
    return Fit3(plane, res.x[3:6].copy(),
                dict(zip(nuisances, map(float, res.x[6:6 + len(nuisances)]), strict=True)),
                np.linalg.inv(jtj) if sigma is not None else None,
                tuple(f"{names[i]} ({abs(r[i]):.1f} σ off)" for i in np.flatnonzero(w < 1.0)))


def crlb3(observer: ArrayLike, beacons: list[ArrayLike], plane: MirrorPlane, *,
          target: ArrayLike, sigma: tuple[float, float, float] | np.ndarray,
          n_targets: int = 1,
          nuisances: tuple[str, ...] = (), priors: dict[str, float] | None = None,
          heights: tuple[float, ...] | None = None,
          fronts: tuple[float, ...] | None = None,
          pan_deg: float | None = None, position_sigma: float = 0.0) -> np.ndarray:
    """The Cramér–Rao bound of (yaw, lean, ρ, x, y, z, *nuisances, *each beacon's plan
    offset where ``position_sigma``) at the truth, for
    Gaussian errors of these σ's: the inverse of the Fisher information the fit of
    :func:`solve_lsq3` weighs (no estimator that is unbiased does better).

    Raises
    ------
    SolverError
        The geometry does not determine the unknowns.
    """
    _check_objects(len(beacons), heights, fronts)
    o, t = np.asarray(observer, float), np.asarray(target, float)
    ot = observe3(o, plane, t)  # the target must stand before the glass
    seen = [seen3(o, plane, b) for b in beacons]
    seen += [(ot.alpha_deg, ot.elevation_deg, ot.d_total)] * n_targets
    p = _Problem(o, [np.asarray(b, float) for b in beacons], np.array(seen, float), sigma,
                 tuple(nuisances), dict(priors or {}), flip=plane.flip,
                 heights=None if heights is None else tuple(heights),
                 fronts=None if fronts is None else tuple(fronts), pan_deg=pan_deg,
                 position_sigma=position_sigma)
    x = p.start([plane.yaw_deg, plane.lean_deg, plane.rho, *t])
    J = _jacobian(p, x)
    info = J.T @ J
    if np.linalg.cond(info) > 1e14:
        raise SolverError("the geometry does not determine the mirror's plane and the target")
    return np.linalg.inv(info)


def _check_objects(n_beacons: int, heights: tuple[float, ...] | None,
                   fronts: tuple[float, ...] | None) -> None:
    """One height (and face offset) per beacon and one for the target, or none."""
    for name, values in (("heights", heights), ("fronts", fronts)):
        if values is not None and len(values) != n_beacons + 1:
            raise SolverError(f"{name}: {len(values)} given for {n_beacons} beacon(s) and the "
                              f"target ({n_beacons + 1} expected)")
    if fronts is not None and heights is None:
        raise SolverError("fronts: given without heights (they model a detector's readings)")


def _jacobian(p: _Problem, x: np.ndarray) -> np.ndarray:
    """The weighted residuals' Jacobian at ``x`` by central differences (steps a
    millionth of each parameter's scale: 1e-6° and 1e-6 cm, 1e-9 in the scale; 1e-6/cm
    in the power, in which the model is linear: exact at any step)."""
    steps = np.full(len(x), 1e-6)
    steps[6:6 + len(p.nuisances)] = [1e-9 if n == "scale" else 1e-6 for n in p.nuisances]
    cols = []
    for k, h in enumerate(steps):
        e = np.zeros(len(x))
        e[k] = h
        cols.append((p.residuals(x + e) - p.residuals(x - e)) / (2 * h))
    return np.column_stack(cols)

