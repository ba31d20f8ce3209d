"""The paper's Table 1 protocol in three dimensions: the same noisy draws, with a
mirror that leans and objects raised off the board, solved by the 3-D closed form
(:func:`closed_form3_unchecked`) and, on the same draws, by the planar one.

Each image is seen at (α, ε, d_total); ε, its elevation, takes Gaussian noise as α does
(σ_ε = σ_α unless given: a pixel's error moves an image's bearing and its row alike).
The planar solve takes α and d_total as they are, so its error says what ignoring the
third dimension costs on the same measurements.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.geometry import yaw_difference
from solver.montecarlo import Table1Geometry, largest_share
from solver.sltr import closed_form_unchecked
from solver.sltr3d import ZHAT, MirrorPlane, direction, observe3


@dataclass(frozen=True)
class Rise:
    """What makes Table 1's set-up three-dimensional, in the table's units: the mirror's
    lean (deg, its top away from its face, about its bottom edge on the board), the
    heights of the target's and the beacon's bases and of the camera above the board."""

    lean_deg: float = 0.0
    target_z: float = 0.0
    beacon_z: float = 0.0
    camera_z: float = 0.0

    @property
    def flat(self) -> bool:
        """Whether nothing rises: the planar protocol."""
        return not any((self.lean_deg, self.target_z, self.beacon_z, self.camera_z))


@dataclass(frozen=True)
class Layout3:
    """Where everything stands in 3-D and what the camera sees of the beacon and the
    target: (α, ε, d_total) each."""

    observer: np.ndarray
    plane: MirrorPlane
    target: np.ndarray
    beacon: np.ndarray
    beacon_seen: tuple[float, float, float]
    target_seen: tuple[float, float, float]
    target_reflection_point: np.ndarray


def layout3(geometry: Table1Geometry, rise: Rise) -> Layout3:
    """:meth:`Table1Geometry.layout`'s mirror, target and beacon, raised by ``rise``.

    Raises
    ------
    SolverError
        The lean puts the target, the beacon or the camera behind the glass.
    """
    lay = geometry.layout()
    o = np.array([0.0, 0.0, rise.camera_z])
    plane = MirrorPlane.from_pose(np.r_[lay.mirror_point, 0.0], lay.yaw_deg, rise.lean_deg,
                                  toward=o)
    target, beacon = np.r_[lay.target, rise.target_z], np.r_[lay.beacon, rise.beacon_z]
    ob, ot = observe3(o, plane, beacon), observe3(o, plane, target)
    return Layout3(o, plane, target, beacon, (ob.alpha_deg, ob.elevation_deg, ob.d_total),
                   (ot.alpha_deg, ot.elevation_deg, ot.d_total), ot.reflection_point)


@dataclass(frozen=True)
class BatchEstimate3:
    """Closed-form 3-D estimates of a batch of draws (NaN where a draw gives none): the
    plane's unit normals and offsets, the targets and their reflection points."""

    normal: np.ndarray  # (k, 3)
    rho: np.ndarray  # (k,)
    target: np.ndarray  # (k, 3)
    target_reflection_point: np.ndarray  # (k, 3)

    @property
    def yaw_deg(self) -> np.ndarray:
        """Each plane's line's bearing on the board (deg, mod 180)."""
        along = np.cross(ZHAT, self.normal)
        return np.degrees(np.arctan2(along[:, 1], along[:, 0])) % 180.0

    @property
    def lean_deg(self) -> np.ndarray:
        """Each plane's lean: its normal's elevation (deg)."""
        return np.degrees(np.arcsin(np.clip(self.normal[:, 2], -1.0, 1.0)))


def closed_form3_unchecked(observer: ArrayLike, beacon: ArrayLike,
                           beacon_seen: tuple[ArrayLike, ArrayLike, ArrayLike],
                           *, target_seen: tuple[ArrayLike, ArrayLike, ArrayLike]
                           ) -> BatchEstimate3:
    """:func:`~solver.sltr3d.solve_single3`'s arithmetic over a batch of draws (each
    seen as arrays of α, ε, d_total), without its checks: a draw whose target image
    lands on the camera's side of its plane, or whose beacon image meets the beacon,
    gives NaN."""
    o, b = np.asarray(observer, float), np.asarray(beacon, float)
    vb = o + np.asarray(beacon_seen[2], float)[:, None] * direction(*beacon_seen[:2])
    gap = b - vb
    n = gap / np.linalg.norm(gap, axis=1)[:, None]
    rho = np.einsum("ij,ij->i", n, (b + vb) / 2.0)
    vt = o + np.asarray(target_seen[2], float)[:, None] * direction(*target_seen[:2])
    side = np.einsum("ij,ij->i", vt, n) - rho
    target = vt - 2.0 * side[:, None] * n
    ray = vt - o
    hit = o + ((rho - n @ o) / np.einsum("ij,ij->i", n, ray))[:, None] * ray
    bad = ~(side < 0)  # the target's image must lie behind the plane (NaN included)
    target[bad], hit[bad] = np.nan, np.nan
    return BatchEstimate3(n, rho, target, hit)


@dataclass(frozen=True)
class RowErrors3:
    """One row's RMSEs over its draws, in 3-D: the reflector (the target's reflection
    point), the target, the plane's yaw and lean; the planar closed form's target error
    in plan on the same draws; how many draws gave no estimate (3-D); and the median and
    largest draw's share of the target's error, as :class:`~solver.montecarlo.RowErrors`."""

    rmse_ref: float
    rmse_tar: float
    rmse_yaw_deg: float
    rmse_lean_deg: float
    rmse_tar_planar: float
    failed: int
    median_tar: float
    largest_share_tar: float


def run_row3(sigma_alpha_deg: float, sigma_d: float, iterations: int = 200, *,
             layout: Layout3, rng: int | np.random.Generator | None = 0,
             beacon_sigma: tuple[float, float] | None = None, shared_alpha_deg: float = 0.0,
             sigma_elevation_deg: float | None = None) -> RowErrors3:
    """One row in 3-D: ``iterations`` draws of every α, ε and d_total (σ_d absolute;
    ``beacon_sigma``: the beacon's (σ_α, σ_d) where they differ; ``shared_alpha_deg``:
    σ of an offset added to both α's alike; σ_ε each image's σ_α unless
    ``sigma_elevation_deg`` is given), solved in 3-D and in the plane."""
    rng = np.random.default_rng(rng)
    k = iterations
    sab, sdb = beacon_sigma or (sigma_alpha_deg, sigma_d)
    se_b = sab if sigma_elevation_deg is None else sigma_elevation_deg
    se_t = sigma_alpha_deg if sigma_elevation_deg is None else sigma_elevation_deg
    (ab, eb, db), (at, et, dt) = layout.beacon_seen, layout.target_seen
    bseen = (ab + rng.normal(0, sab, k), eb + rng.normal(0, se_b, k), db + rng.normal(0, sdb, k))
    tseen = (at + rng.normal(0, sigma_alpha_deg, k), et + rng.normal(0, se_t, k),
             dt + rng.normal(0, sigma_d, k))
    if shared_alpha_deg:
        delta = rng.normal(0, shared_alpha_deg, k)
        bseen, tseen = (bseen[0] + delta, *bseen[1:]), (tseen[0] + delta, *tseen[1:])
    est = closed_form3_unchecked(layout.observer, layout.beacon, bseen, target_seen=tseen)
    ok = np.isfinite(est.target).all(axis=1)
    tar = np.linalg.norm(est.target[ok] - layout.target, axis=1)
    ref = np.linalg.norm(est.target_reflection_point[ok] - layout.target_reflection_point, axis=1)
    yaw = yaw_difference(est.yaw_deg[ok], layout.plane.yaw_deg)
    lean = est.lean_deg[ok] - layout.plane.lean_deg
    flat = closed_form_unchecked(layout.observer[:2], layout.beacon[:2], bseen[0],
                                 beacon_d_total=bseen[2], target_alpha_deg=tseen[0],
                                 target_d_total=tseen[2])
    plan = np.linalg.norm(flat.target - layout.target[:2], axis=1)
    plan = plan[np.isfinite(plan)]
    rms = lambda e: float(np.sqrt(np.mean(np.square(e)))) if e.size else float("nan")  # noqa: E731
    return RowErrors3(rmse_ref=rms(ref), rmse_tar=rms(tar), rmse_yaw_deg=rms(yaw),
                      rmse_lean_deg=rms(lean), rmse_tar_planar=rms(plan), failed=int(k - ok.sum()),
                      median_tar=float(np.median(tar)) if tar.size else float("nan"),
                      largest_share_tar=largest_share(tar))


@dataclass(frozen=True)
class Table3:
    """The 3-D protocol's result: the set-up, the draws per row, each row's σ's (σ_α
    deg, σ_d absolute, and the beacon's where they differ) and its errors."""

    geometry: Table1Geometry
    rise: Rise
    iterations: int
    rows: tuple[tuple[tuple, RowErrors3], ...]

    def to_json(self) -> dict:
        """``montecarlo --json``'s document for a 3-D set-up."""
        lay = layout3(self.geometry, self.rise)
        return {"geometry": {**asdict(self.geometry), **asdict(self.rise),
                             "mirror_yaw_deg": lay.plane.yaw_deg,
                             "mirror_lean_deg": lay.plane.lean_deg,
                             "target": lay.target.tolist(), "beacon": lay.beacon.tolist(),
                             "target_seen": list(lay.target_seen),
                             "beacon_seen": list(lay.beacon_seen)},
                "iterations": self.iterations,
                "rows": [{"sigma_alpha_deg": row[0], "sigma_d": row[1],
                          "sigma_d_units": "absolute (the table's distance units)",
                          **({"beacon_sigma_alpha_deg": row[4][0], "beacon_sigma_d": row[4][1]}
                             if len(row) > 4 else {}), **asdict(errors)}
                         for row, errors in self.rows]}


def table3(iterations: int, geometry: Table1Geometry, rise: Rise, *, rows: tuple,
           rng: int | np.random.Generator | None = 0,
           sigma_elevation_deg: float | None = None) -> Table3:
    """Every row of :func:`~solver.montecarlo.table_rows`'s form (σ_α, σ_d, the paper's
    two figures, and optionally the beacon's σ's and a shared α offset) in 3-D.

    Raises
    ------
    SolverError
        A lean that puts an object or the camera behind the glass.
    """
    lay = layout3(geometry, rise)
    rng = np.random.default_rng(rng)
    return Table3(geometry, rise, iterations, tuple(
        (row, run_row3(row[0], row[1], iterations, layout=lay, rng=rng,
                       beacon_sigma=row[4] if len(row) > 4 else None,
                       shared_alpha_deg=row[5] if len(row) > 5 else 0.0,
                       sigma_elevation_deg=sigma_elevation_deg)) for row in rows))
