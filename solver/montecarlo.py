"""The paper's Table 1 protocol: noisy measurements, RMSE of reflector and target.

Section 5: d_total = 5, α = 70°, zero-mean Gaussian noise on the angle of arrival and
the distance, 200 iterations per row.  The paper leaves unstated where the mirror and
the beacon stand; :class:`Table1Geometry` makes them explicit parameters.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from solver.geometry import line_normal, unit, yaw_difference
from solver.measurements import ObjectSigmas
from solver.sltr import closed_form_unchecked, observe

# v(α) [deg], v(d_total) [distance units], RMSE(ref), RMSE(tar): the paper's Table 1
PAPER_TABLE1 = (
    (1.73, 0.16, 0.036, 0.10),
    (2.60, 0.29, 0.09, 0.12),
    (1.46, 0.41, 0.23, 0.15),
)


@dataclass(frozen=True)
class Table1Layout:
    """Where :class:`Table1Geometry` puts everything, and the exact α, d_total of the
    beacon and the target."""

    mirror_point: np.ndarray  # the target's reflection point (the reflector)
    yaw_deg: float
    target: np.ndarray
    beacon: np.ndarray
    beacon_alpha: float
    beacon_d: float
    target_alpha: float
    target_d: float
    target_reflection_point: np.ndarray


@dataclass(frozen=True)
class Table1Geometry:
    """The set-up of the Monte Carlo runs (observer at the origin).

    The target's ray leaves at ``alpha_deg`` and meets the mirror at ``d1``; the mirror
    turns ``incidence_deg`` from facing that ray square-on; the target lies
    ``d_total − d1`` beyond.  The beacon stands ``beacon_depth`` in front of the mirror
    and ``beacon_along`` along it from the target's reflection point.
    """

    alpha_deg: float = 70.0
    d_total: float = 5.0
    d1: float = 3.0
    incidence_deg: float = 30.0
    beacon_depth: float = 0.5
    beacon_along: float = 0.3

    def layout(self) -> Table1Layout:
        """Mirror point and yaw, target and beacon positions, and their exact α, d."""
        if not 0 < self.d1 < self.d_total:
            raise ValueError(f"need 0 < d1 < d_total, got d1={self.d1}, d_total={self.d_total}")
        r = self.d1 * unit(self.alpha_deg)
        yaw = self.alpha_deg - 90.0 + self.incidence_deg
        target = r + (self.d_total - self.d1) * unit(2 * yaw - self.alpha_deg)
        n = line_normal(yaw)
        n = n if n @ (-r) > 0 else -n  # towards the observer
        beacon = r + self.beacon_depth * n + self.beacon_along * unit(yaw)
        o = np.zeros(2)
        ob = observe(o, r, yaw, point=beacon)
        ot = observe(o, r, yaw, point=target)
        return Table1Layout(mirror_point=r, yaw_deg=float(yaw), target=target, beacon=beacon,
                            beacon_alpha=float(ob.alpha_deg), beacon_d=float(ob.d_total),
                            target_alpha=float(ot.alpha_deg), target_d=float(ot.d_total),
                            target_reflection_point=np.asarray(ot.reflection_point))


@dataclass(frozen=True)
class RowErrors:
    """One row's RMSEs over its draws: the reflector (the target's reflection point), the
    target, the mirror's yaw; and how many draws gave no finite estimate.  Beside them,
    the reflector's and the target's median errors and the share of each one's summed
    squared error that its single largest draw holds: a mirror estimated nearly along the
    target's ray puts the reflection point (and the target) far off, and where one draw
    holds most of the sum the RMSE follows that draw, not the σ's (it does not settle as
    draws grow)."""

    rmse_ref: float
    rmse_tar: float
    rmse_yaw_deg: float
    failed: int
    median_ref: float = float("nan")
    median_tar: float = float("nan")
    largest_share_ref: float = float("nan")
    largest_share_tar: float = float("nan")


@dataclass(frozen=True)
class Table1Row:
    """A row of Table 1: its σ's, the paper's figures (NaN where it has none) and ours."""

    sigma_alpha_deg: float
    sigma_d: float  # absolute, in the table's distance units (the paper's convention)
    paper_rmse_ref: float
    paper_rmse_tar: float
    ours: RowErrors
    # the beacon's (σ_α, σ_d) where they differ from the target's (an error model's row)
    beacon_sigma: tuple[float, float] | None = None
    # σ (deg) of an α offset both images share (an error model's pan spread)
    shared_alpha_deg: float = 0.0

    def to_json(self) -> dict:
        """The row as ``montecarlo --json`` writes it."""
        out = {"sigma_alpha_deg": self.sigma_alpha_deg, "sigma_d": self.sigma_d,
               "sigma_d_units": "absolute (the table's distance units)",
               "paper_rmse_ref": self.paper_rmse_ref, "paper_rmse_tar": self.paper_rmse_tar,
               **asdict(self.ours)}
        if self.beacon_sigma is not None:
            out["beacon_sigma_alpha_deg"], out["beacon_sigma_d"] = self.beacon_sigma
        if self.shared_alpha_deg:
            out["shared_alpha_deg"] = self.shared_alpha_deg
        return out


@dataclass(frozen=True)
class Table1:
    """:func:`table1`'s result: the geometry, the draws per row and the rows."""

    geometry: Table1Geometry
    iterations: int
    rows: tuple[Table1Row, ...]

    def to_json(self) -> dict:
        """``montecarlo --json``'s document."""
        lay = self.geometry.layout()
        return {"geometry": {**asdict(self.geometry),
                             "mirror_point": lay.mirror_point.tolist(),
                             "mirror_yaw_deg": float(lay.yaw_deg),
                             "target": lay.target.tolist(), "beacon": lay.beacon.tolist()},
                "iterations": self.iterations, "rows": [r.to_json() for r in self.rows]}


def run_row(sigma_alpha_deg: float, sigma_d: float, iterations: int = 200,
            *, geometry: Table1Geometry | None = None,
            rng: int | np.random.Generator | None = 0,
            beacon_sigma: tuple[float, float] | None = None,
            shared_alpha_deg: float = 0.0) -> RowErrors:
    """One row: RMSE of the reflector (the target's reflection point), its yaw, and the
    target, over ``iterations`` noisy draws of all four measurements (vectorized); σ_d
    absolute; ``beacon_sigma``: the beacon's (σ_α, σ_d) where they differ;
    ``shared_alpha_deg``: σ of an offset added to both α's alike."""
    g = (geometry or Table1Geometry()).layout()
    rng = np.random.default_rng(rng)
    k = iterations
    sab, sdb = beacon_sigma or (sigma_alpha_deg, sigma_d)
    ab = g.beacon_alpha + rng.normal(0, sab, k)
    db = g.beacon_d + rng.normal(0, sdb, k)
    at = g.target_alpha + rng.normal(0, sigma_alpha_deg, k)
    dt = g.target_d + rng.normal(0, sigma_d, k)
    if shared_alpha_deg:  # drawn after the others: rows without it draw as before
        delta = rng.normal(0, shared_alpha_deg, k)
        ab, at = ab + delta, at + delta
    est = closed_form_unchecked(np.zeros(2), g.beacon, ab, beacon_d_total=db, target_alpha_deg=at,
                                target_d_total=dt)
    ok = np.isfinite(est.target).all(axis=1) & np.isfinite(
        est.target_reflection_point).all(axis=1)
    ref_err = np.linalg.norm(est.target_reflection_point[ok] - g.target_reflection_point,
                             axis=1)
    tar_err = np.linalg.norm(est.target[ok] - g.target, axis=1)
    yaw_err = yaw_difference(est.yaw_deg[ok], g.yaw_deg)
    return RowErrors(rmse_ref=float(np.sqrt(np.mean(ref_err ** 2))),
                     rmse_tar=float(np.sqrt(np.mean(tar_err ** 2))),
                     rmse_yaw_deg=float(np.sqrt(np.mean(yaw_err ** 2))),
                     failed=int(k - ok.sum()),
                     median_ref=float(np.median(ref_err)), median_tar=float(np.median(tar_err)),
                     largest_share_ref=largest_share(ref_err),
                     largest_share_tar=largest_share(tar_err))


def largest_share(err: np.ndarray) -> float:
    """The share of ``sum(err²)`` that the largest draw holds (NaN for no draws)."""
    sq = np.asarray(err, float) ** 2
    return float(sq.max() / sq.sum()) if sq.size and sq.sum() > 0 else float("nan")


def table1(iterations: int = 200, geometry: Table1Geometry | None = None,
           rng: int | np.random.Generator | None = 0,
           *, rows: tuple = PAPER_TABLE1) -> Table1:
    """All rows of Table 1, ours beside the paper's."""
    rng = np.random.default_rng(rng)
    g = geometry or Table1Geometry()
    def tail(row: tuple) -> dict:  # a row's optional σ's: the beacon's, a shared α offset
        return dict(zip(("beacon_sigma", "shared_alpha_deg"), row[4:], strict=False))

    return Table1(g, iterations, tuple(
        Table1Row(*row[:4], run_row(row[0], row[1], iterations, geometry=g, rng=rng, **t), **t)
        for row, t in ((row, tail(row)) for row in rows)))


def table_rows(sigmas: list[tuple[float, float]] | None = None,
               relative: ObjectSigmas | None = None,
               geometry: Table1Geometry | None = None,
               *, d_totals: tuple[float, float] | None = None) -> tuple:
    """The rows to run: the paper's (or ``sigmas``: (σ_α deg, σ_d relative) pairs without
    paper figures), plus one for an error model's relative σ's (the target's and the
    beacon's); relative σ_d's become absolute at each object's own d_total (the
    geometry's, or ``d_totals``: the target's and the beacon's, as a 3-D set-up sees
    them)."""
    nan = float("nan")
    lay = (geometry or Table1Geometry()).layout()
    d_t, d_b = d_totals or (lay.target_d, lay.beacon_d)
    rows = PAPER_TABLE1 if not sigmas else tuple((a, d * d_t, nan, nan, (a, d * d_b))
                                                 for a, d in sigmas)
    if relative is not None:
        t, b = relative.target, relative.beacons[0]
        rows = (*rows, (t.alpha_deg, t.d_total_rel * d_t, nan, nan,
                        (b.alpha_deg, b.d_total_rel * d_b), relative.shared_alpha_deg))
    return rows
