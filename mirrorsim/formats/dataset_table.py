"""The dataset table's columns, declared once: the rows are built from them, the card
lists them, :mod:`mirrorsim.pipelines.errormodel` reads them by these names and a test
holds every row to them.

A column for each of the target and the beacon is named ``<object>_<name>``
(:func:`object_column`); the bench imperfections' columns come from their registry.  A
scene with several beacons has the same columns for its second, third… beacon, named
``beacon2_<name>``, ``beacon3_<name>``… (:func:`beacon_kind`); :func:`image_rows` turns
such a table into one row per beacon image, as the error model reads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mirrorsim.scene.imperfections import REGISTRY
from solver.selfcal import NUISANCES, NUISANCES_3D


@dataclass(frozen=True)
class Column:
    """One column: its name, units ('' where none) and meaning."""

    name: str
    units: str
    doc: str


OBJECTS = ("target", "beacon")
MAX_BEACONS = 4  # a dataset spec's most beacons a scene (its ``beacon.count``)

RUN = (
    Column("index", "", "the scene's number"), Column("scene", "", "its name"),
    Column("seed", "", "the dataset's seed"), Column("schema", "", "row layout version"),
    Column("render_seed", "", "the render's seed (the scene's number)"),
    Column("variant", "", "Mitsuba variant"),
    Column("spp", "", "samples per pixel in the mirror's image"),
    Column("background_spp", "", "samples per pixel outside it"),
    Column("beacon_spp", "", "samples per pixel in each beacon's image (one under 40 px "
           "tall, board to tip: more, as its truth's render block says)"),
    Column("sampler", "", "Mitsuba sampler"),
    Column("calibrate", "", "the nuisances the solver estimated (`--calibrate`; empty: "
                            "plain least squares)"),
    Column("calibrate_priors", "", "the σ of each nuisance's prior, as `--prior` takes them "
                                   "(`pan=0.3,scale=0.006`; empty: none)"),
    Column("geometry", "", "how the scene was solved: `planar`, or `3d` (a spec with a 3-D "
                           "key: each image's elevation measured, the mirror's plane and "
                           "the target solved in 3-D)"),
    Column("error", "", "why the scene failed (empty if fine)"),
)
SCENE = (
    Column("camera_x", "cm", "camera position"), Column("camera_y", "cm", "camera position"),
    Column("camera_height", "cm", "camera height"),
    Column("camera_pan_deg", "deg", "optical axis bearing"),
    Column("hfov_deg", "deg", "horizontal field of view"),
    Column("mirror_x", "cm", "mirror centre"), Column("mirror_y", "cm", "mirror centre"),
    Column("mirror_yaw_deg", "deg", "mirror line direction, [0, 180)"),
    Column("mirror_width", "cm", "mirror width"), Column("mirror_height", "cm", "mirror height"),
    Column("mirror_lean_deg", "deg", "the mirror's lean about its bottom edge (+: its top "
                                     "away from its face)"),
    Column("target_x", "cm", "target position"), Column("target_y", "cm", "target position"),
    Column("target_z", "cm", "its base above the board"),
    Column("beacons", "", "how many beacons the scene has (columns `beacon_*` for the first, "
                          "`beacon2_*`… for the others)"),
    Column("pencil_height_cm", "cm", "the first beacon's pencil height"),
)
# what the solver was given besides the images (the capture record's: believed values)
KNOWN = (
    Column("observer_x", "cm", "camera position the solver was given"),
    Column("observer_y", "cm", "camera position the solver was given"),
    Column("observer_pan_deg", "deg", "pan the camera's mount reported"),
    Column("fx_px", "px", "the camera's focal length"),
    Column("beacon_known_x", "cm", "beacon position the solver was given"),
    Column("beacon_known_y", "cm", "beacon position the solver was given"),
    Column("beacon_sigma", "cm", "how well the solver took each beacon's position to be "
                                 "known, per axis (`--beacon-sigma`; 0: exactly)"),
)
# for each beacon after the first, as beacon<k>_<name> (KNOWN's beacon columns' names)
BEACON_KNOWN = tuple(Column(c.name.removeprefix("beacon_"), c.units, c.doc)
                     for c in KNOWN if c.name.startswith("beacon_known_"))
# for each of OBJECTS, as <object>_<name>
PER_OBJECT = (
    Column("pos_x", "cm", "position"), Column("pos_y", "cm", "position"),
    Column("pos_z", "cm", "its base above the board"),
    Column("alpha_true", "deg", "exact α (3-D: what an exact detector reads)"),
    Column("d_true", "cm", "exact d_total (3-D: the path's length, as an exact detector "
                           "reads it)"),
    Column("d1", "cm", "camera → reflection point"),
    Column("d2", "cm", "reflection point → object"),
    Column("off_axis_deg", "deg", "bearing of the image off the optical axis (+ left)"),
    Column("incidence_deg", "deg", "camera ray against the mirror's normal"),
    Column("height_px_true", "px", "exact image height of the upright axis"),
    Column("alpha_meas", "deg", "measured α"), Column("d_meas", "cm", "measured d_total"),
    Column("alpha_err", "deg", "measured − true α"),
    Column("d_rel_err", "1", "(measured − true) / true d_total"),
    Column("elevation_true", "deg", "exact elevation (3-D: what an exact detector reads; "
                                    "null in a planar row)"),
    Column("elevation_meas", "deg", "measured elevation (null in a planar row)"),
    Column("elevation_err", "deg", "measured − true elevation (null in a planar row)"),
    Column("clipped", "", "the detector found the image clipped"),
    # what the frame showed of the image (the error model's σ features)
    Column("height_px_meas", "px", "measured image height"),
    Column("contrast", "1", "relative contrast of the image's edges"),
    Column("noise", "1", "the frame's relative noise (on the target panel)"),
    Column("jpeg_quality", "", "the frame's JPEG quality as its file says (0: lossless)"),
    Column("sigma_alpha_deg", "deg", "σ of the measured α, from the error model (3-D: "
                                     "what the 3-D solve weighed it with, the model's "
                                     "widened)"),
    Column("sigma_d_rel", "1", "σ of the measured d_total, relative (a fraction), from the "
                               "error model (3-D: likewise)"),
    Column("sigma_elevation_deg", "deg", "σ of the measured elevation the 3-D solve weighed "
                                         "it with (null in a planar row)"),
)
SOLUTION = (
    Column("est_target_x", "cm", "estimated target"),
    Column("est_target_y", "cm", "estimated target"),
    Column("est_mirror_yaw_deg", "deg", "estimated mirror line direction"),
    Column("err_target_cm", "cm", "target error (3-D: the 3-D distance)"),
    Column("err_mirror_yaw_deg", "deg", "mirror yaw error"),
    Column("err_mirror_offset_cm", "cm",
           "estimated line's distance from the true reflection point"),
    Column("err_reflection_point_cm", "cm", "reflection point error"),
    Column("target_ellipse95_major_cm", "cm", "semi-major axis of the solver's 95 % ellipse "
                                              "(3-D: its Gaussian 95 % ellipsoid's)"),
    Column("target_cov_xx", "cm²", "the estimated target's covariance"),
    Column("target_cov_xy", "cm²", "the estimated target's covariance"),
    Column("target_cov_yy", "cm²", "the estimated target's covariance"),
    Column("target_mahalanobis", "1",
           "true target's distance from the estimate in σ's of that covariance (3-D: of "
           "its 3×3 covariance)"),
    # a 3-D solve's (null in a planar row)
    Column("est_target_z", "cm", "estimated target's base above the board"),
    Column("est_mirror_lean_deg", "deg", "estimated mirror lean"),
    Column("err_target_height_cm", "cm", "estimated − true height of the target's base"),
    Column("err_mirror_lean_deg", "deg", "estimated − true mirror lean"),
    Column("target_cov_xz", "cm²", "the estimated target's covariance"),
    Column("target_cov_yz", "cm²", "the estimated target's covariance"),
    Column("target_cov_zz", "cm²", "the estimated target's covariance"),
    Column("planar_err_target_cm", "cm", "the planar solve's target error (in plan) on the "
                                         "same frames"),
    Column("est_pitch_offset_deg", "deg", "estimated pitch offset (null unless `calibrate` "
                                          "names it)"),
    Column("est_pitch_offset_deg_sd", "deg", "σ of the estimated pitch offset (likewise)"),
    # the nuisances self-calibration estimates (null where not estimated)
    *(Column(f"est_{key}{sd}", units, f"{what} {doc} (null unless `calibrate` names it)")
      for key, units, doc in (("pan_offset_deg", "deg", "pan offset δ"),
                              ("range_scale", "1", "range scale s"),
                              ("mirror_power_per_cm", "1/cm", "mirror's power 1/R"))
      for sd, what in (("", "estimated"), ("_sd", "σ of the estimated"))),
)
assert ({f"est_{key}" for key, _ in (*NUISANCES.values(), *NUISANCES_3D.values())}
        <= {c.name for c in SOLUTION})
BENCH = tuple(Column(c.name, c.units, c.doc) for imp in REGISTRY for c in imp.columns)
TIMING = (Column("seconds_sample", "s", "drawing the scene"),
          Column("seconds_total", "s", "the whole scene"))


def object_column(kind: str, name: str) -> str:
    """The column of ``name`` (one of PER_OBJECT's) for ``kind`` (target, beacon, or
    :func:`beacon_kind`'s beacon2…)."""
    return f"{kind}_{name}"


def beacon_kind(k: int) -> str:
    """The column prefix of a scene's beacon k (0-based): ``beacon``, ``beacon2``…"""
    return "beacon" if k == 0 else f"beacon{k + 1}"


def _slot_columns(k: int) -> tuple[Column, ...]:
    """The columns of beacon k ≥ 1 (0-based): its known position and its PER_OBJECT's."""
    kind = beacon_kind(k)
    return (*(Column(object_column(kind, c.name), c.units, f"{kind}: {c.doc}")
              for c in BEACON_KNOWN),
            *(Column(object_column(kind, c.name), c.units, f"{kind}: {c.doc}")
              for c in PER_OBJECT))


# every column of a row, in declaration order (a failed scene's row has RUN's, and TIMING's)
COLUMNS = (*RUN, *SCENE, *KNOWN,
           *(Column(object_column(k, c.name), c.units, f"{k}: {c.doc}")
             for k in OBJECTS for c in PER_OBJECT),
           *SOLUTION, *BENCH, *TIMING)
NAMES = tuple(c.name for c in COLUMNS)
# the columns of the second, third… beacon: in a row exactly when its scene has them
SLOT_NAMES = {k: tuple(c.name for c in _slot_columns(k)) for k in range(1, MAX_BEACONS)}
# a planar row's null columns (what it did not measure or solve)
PLANAR_NULL = ("elevation_true", "elevation_meas", "elevation_err", "sigma_elevation_deg")
SOLUTION_3D = ("est_target_z", "est_mirror_lean_deg", "err_target_height_cm",
               "err_mirror_lean_deg", "target_cov_xz", "target_cov_yz", "target_cov_zz",
               "planar_err_target_cm", "est_pitch_offset_deg", "est_pitch_offset_deg_sd")
# the columns each layout added besides the bench imperfections', with the value a row of
# an older layout had for them: schema 3 several beacons and self-calibration, schema 4
# the self-calibration's priors, schema 5 what the frame showed of each image (unknown for
# an older row: null), schema 6 the 3-D columns (an older row's scene was planar).  The
# first layout is 2.
FIRST_SCHEMA = 2
_ADDED = {3: {"beacons": 1, "calibrate": "", "beacon_sigma": 0.0,
              **{f"est_{key}{sd}": None for key, _ in NUISANCES.values()
                 for sd in ("", "_sd")}},
          4: {"calibrate_priors": ""},
          5: {"pencil_height_cm": None,
              **{object_column(k, c): None for k in OBJECTS
                 for c in ("height_px_meas", "contrast", "noise", "jpeg_quality")}},
          6: {"geometry": "planar", "mirror_lean_deg": 0.0, "target_z": 0.0,
              **{object_column(k, c): v for k in OBJECTS
                 for c, v in (("pos_z", 0.0), *((c, None) for c in PLANAR_NULL))},
              **{c: None for c in SOLUTION_3D}}}


def layouts(registry: tuple = REGISTRY) -> tuple[int, dict[int, dict[str, Any]]]:
    """The row layout this mirrorsim writes, and the columns each layout added with the
    value an older row had for them: :data:`_ADDED`'s, and each imperfection's from its
    registry entry (``since``: its layout; an older row's scene was ideal in it)."""
    added = {k: dict(v) for k, v in _ADDED.items()}
    for imp in registry:
        if imp.since > FIRST_SCHEMA:
            added.setdefault(imp.since, {}).update({c.name: c.ideal for c in imp.columns})
    return max(added), added


# the layout of the rows this mirrorsim writes, and what each layout added
SCHEMA, ADDED_IN = layouts()
# the older layouts a table may hold, read with ADDED_IN's values
OLDER_SCHEMAS = tuple(range(FIRST_SCHEMA, SCHEMA))


def older_values(schema: int, beacons: int = 1) -> dict[str, Any]:
    """What a row of layout ``schema`` (of ``beacons`` beacons) had for the columns added
    since: a beacon's column for each of its beacons (``beacon2_*``…)."""
    out = {k: v for s, added in ADDED_IN.items() if s > schema for k, v in added.items()}
    per_object = {c.name for c in PER_OBJECT}
    for name, v in list(out.items()):
        rest = name.removeprefix("beacon_")
        if rest != name and rest in per_object:
            out.update({object_column(beacon_kind(k), rest): v for k in range(1, beacons)})
    return out


def checked_row(row: dict) -> dict:
    """``row`` if it holds declared columns only (and, when the scene did not fail, all of
    them, with its beacons' slots): a misspelt or forgotten column fails here, where the
    row is made, not in a reader of the table far from the change."""
    names = set(row) - {"traceback"}
    count = 1 if row.get("error") else int(row.get("beacons") or 1)
    slots = {n for k in range(1, count) for n in SLOT_NAMES.get(k, ())}
    unknown = names - set(NAMES) - slots
    missing = set() if row.get("error") else (set(NAMES) | slots) - names
    if unknown or missing:
        raise ValueError(f"dataset row off its declared columns: unknown {sorted(unknown)}, "
                         f"missing {sorted(missing)}")
    return row


@dataclass(frozen=True)
class DatasetRow:
    """One scene's row, written as ``rows/<scene>.json``: its columns by their declared
    names (checked when the row is made), for a scene that failed the traceback, and the
    SHA-256 of each of its scene's files in ``frames/<scene>/`` as the row found them
    (``files``; empty in a row made before they were recorded)."""

    columns: dict[str, Any]
    traceback: str = ""
    files: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        checked_row(self.columns)

    def __getitem__(self, name: str) -> Any:
        """A column's value, by its declared name."""
        return self.columns[name]

    @property
    def index(self) -> int:
        """The scene's number."""
        return self.columns["index"]

    @property
    def error(self) -> str:
        """Why the scene failed ('' if it did not)."""
        return self.columns.get("error", "")

    def to_json(self) -> dict:
        """The row file."""
        return {**self.columns, **({"traceback": self.traceback} if self.traceback else {}),
                **({"files": dict(self.files)} if self.files else {})}

    @classmethod
    def from_json(cls, d: dict) -> DatasetRow:
        """Inverse of :meth:`to_json`; a row of an older layout (schema 2: one beacon, no
        self-calibration; 3: no priors; 4: no image features) takes the values its scene
        had for the columns added since."""
        if d.get("schema") in OLDER_SCHEMAS and not d.get("error"):
            d = {**older_values(d["schema"], int(d.get("beacons") or 1)), **d}
        files = d.get("files", {})
        if not (isinstance(files, dict) and all(
                isinstance(k, str) and isinstance(v, str) for k, v in files.items())):
            raise ValueError("its files' SHA-256s are not a mapping of names to digests")
        return cls({k: v for k, v in d.items() if k not in ("traceback", "files")},
                   d.get("traceback", ""), files)


def card_section(group: tuple[Column, ...], prefix: str = "") -> str:
    """A group of columns as the card lists them."""
    return "; ".join(f"`{prefix}{c.name}`" + (f" ({c.units})" if c.units else "")
                     + f": {c.doc}" for c in group)


def usable_rows(cols: dict) -> np.ndarray:
    """Which rows of a table's columns were measured and solved (their ``error`` empty)."""
    return np.array([not e for e in cols.get("error", [""] * len(cols["index"]))], bool)


def require_planar(cols: dict) -> dict:
    """``cols``, refused if it holds 3-D rows (``geometry`` 3d): the validation solves
    each row again in the plane.

    Raises
    ------
    ValueError
        Saying how many rows are 3-D.
    """
    n = sum(g == "3d" for g in cols.get("geometry") or [])
    if n:
        raise ValueError(f"{n} of its rows were solved in 3-D (a 3-D spec's): a model is "
                         "validated by solving planar rows again (a 3-D model is held to "
                         "rendered 3-D scenes: docs/limitations.md)")
    return cols


def focal_lengths(cols: dict) -> np.ndarray:
    """Each row's camera focal length (px); NaN for a table made before it was recorded."""
    n = len(cols["index"])
    return np.asarray(cols["fx_px"], float) if "fx_px" in cols else np.full(n, np.nan)


def counted_once(beacon_of: np.ndarray) -> dict[str, np.ndarray]:
    """Per kind, the image rows (:func:`image_rows`) that count: every beacon's, the
    target's once a scene (its first beacon's row)."""
    return {"target": beacon_of == 0, "beacon": np.ones(len(beacon_of), bool)}


def image_rows(cols: dict) -> tuple[dict, np.ndarray, np.ndarray]:
    """A table's columns with one row per beacon image; and each row's beacon (0-based)
    and scene (its row in ``cols``).

    A row's ``beacon_*`` columns hold its beacon's, every other column its scene's (the
    target's repeated beside each of its beacons); the first beacons of every scene come
    first, in the table's order.  A table of one beacon a scene comes back as it is.
    """
    n = len(cols["index"])
    slots = [k for k in range(1, MAX_BEACONS) if SLOT_NAMES[k][0] in cols]
    scene = np.tile(np.arange(n), 1 + len(slots))
    if not slots:
        return cols, np.zeros(n, int), scene
    count = np.asarray([c or 1 for c in cols.get("beacons", [1] * n)])
    keep = np.concatenate([np.ones(n, bool)] + [count > k for k in slots])
    out = {}
    for name, values in cols.items():
        if any(name in SLOT_NAMES[k] for k in slots):
            continue
        stacked = list(values)
        for k in slots:  # beacon k's own column where it has one, else the scene's
            own = f"{beacon_kind(k)}_{name.removeprefix('beacon_')}"
            stacked += list(cols[own] if name.startswith("beacon_") and own in cols
                            else values)
        out[name] = [v for v, ok in zip(stacked, keep, strict=True) if ok]
    which = np.concatenate([np.zeros(n, int)] + [np.full(n, k) for k in slots])
    return out, which[keep], scene[keep]
