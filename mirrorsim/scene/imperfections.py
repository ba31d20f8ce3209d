"""The bench imperfections, each declared once; a scene's imperfections as named sources.

:data:`REGISTRY` holds one :class:`Imperfection` per imperfection: the field that holds
it (on :class:`~mirrorsim.scene.model.Bench`, or each beacon's believed position), its
scene-file key path, units and bounds, the form a dataset spec draws it in, its dataset
columns and its error-model features.  The scene reader, the spec's scene drawer, the
dataset rows and card and the error model all read it; none lists imperfections of its
own.  Adding one is an entry here (its ``since`` the next row layout), the field on
``Bench``, its rendering hook and its test: the dataset's columns, its layout's version
and the values its older rows take follow from the entry.

The error budget (:mod:`mirrorsim.pipelines.budget`) renders a scene ideal, with each
source alone, and with all; a source is named by its key path (``camera.pan_error``,
``mirror.curvature_radius``, ``beacons[0].known_position``…).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from mirrorsim.scene.model import Bench, Scene

# a dataset's columns as the error model reads them, as float arrays: col(name) for a
# column of the row, obj(name) for the object's own (the target's or the beacon's)
Columns = Callable[[str], np.ndarray]


@dataclass(frozen=True)
class Column:
    """One dataset column an imperfection fills: ``of(scene)`` is its value (the ideal
    bench's value when the imperfection is absent, so that every row has every column)."""

    name: str
    units: str
    doc: str
    of: Callable[[Scene], Any]
    # its value on an ideal bench: what a row written before the imperfection existed
    # had (its scene was ideal in it); a test holds ``of`` of an ideal scene to it
    ideal: Any = 0.0


@dataclass(frozen=True)
class Feature:
    """One error-model feature: ``of(col, obj)`` for the target or the beacon (``obj``
    reads that object's columns), in the form the imperfection's first-order effect is
    linear in."""

    name: str
    doc: str
    of: Callable[[Columns, Columns], np.ndarray]


@dataclass(frozen=True)
class Imperfection:
    """One bench imperfection, declared once.

    ``form`` says how a scene file writes it and a spec draws it: ``angle`` (degrees,
    |value| < ``bound``), ``number`` (``low`` < value < ``high``), ``quality`` (an integer
    in [``low``, ``high``]), ``lens`` ([k1, k2]), ``flag`` (true/false), ``noise``
    ({full_well, read_noise}), ``radius`` (cm; a spec draws its reciprocal, the
    curvature, under ``spec_key``) or ``offset`` (a believed position; a spec draws the
    offset).  ``source``: whether the error budget renders it alone.
    """

    field: str
    key: str
    units: str
    doc: str
    form: str
    columns: tuple[Column, ...]
    features: tuple[Feature, ...] = ()
    bound: float | None = None
    low: float | None = None
    high: float | None = None
    spec_key: str = ""  # the spec's bench-block key path when it differs from ``key``
    source: bool = True
    why: str = ""  # what the bounds mean, for the error message
    # where it acts: "optics" (what Mitsuba renders), "sensor" (after the render: noise,
    # JPEG) or "record" (only what the experimenter believes); see optics_of
    stage: str = "optics"
    # the dataset row layout its columns arrived in: an imperfection added later says the
    # next layout here, and the table's version and its older rows' values follow
    # (:mod:`mirrorsim.formats.dataset_table`)
    since: int = 2

    @property
    def block(self) -> str:
        """The scene file's block (``camera``, ``mirror``, ``calibration``, ``beacons``)."""
        return self.key.split(".")[0]

    @property
    def leaf(self) -> str:
        """The key inside its block."""
        return self.key.split(".")[1]

    @property
    def spec_path(self) -> str:
        """The key path under a spec's ``bench:`` block."""
        return self.spec_key or self.key


def _beacon_offset(scene: Scene, axis: int) -> float:
    b = scene.beacons[0]
    return b.believed[axis] - b.position[axis]


def _off_axis_tan(obj: Columns) -> np.ndarray:
    return np.tan(np.radians(obj("off_axis_deg")))


def _unknown_k1(col: Columns) -> np.ndarray:
    return col("bench_k1") * (col("bench_distortion_known") == 0)


def _where_noise(col: Columns, value: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    fw = col("bench_full_well")
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(fw > 0, value(fw), 0.0)


def _mirror_power(col: Columns, obj: Columns) -> np.ndarray:
    # a mirror of curvature 1/R changes d_total by −2·cos i·d1·d2/(R·d_total): this
    # feature's d coefficient should come out −1
    cos_i = np.cos(np.radians(obj("incidence_deg")))
    return (2 * cos_i * obj("d1") * obj("d2") * col("bench_curvature_per_cm")
            / obj("d_true"))


def _plain(name: str, column: str, units: str, doc: str) -> tuple[Column, ...]:
    return (Column(column, units, doc, lambda s: getattr(s.bench, name),
                   ideal=getattr(Bench(), name)),)


def _linear(name: str, column: str, doc: str) -> tuple[Feature, ...]:
    return (Feature(name, doc, lambda col, _obj: col(column)),)


# In docs/scenes.md's order, which is also the dataset's column order and the order a spec's
# bench block is drawn in (so the same seed draws the same scenes).
REGISTRY: tuple[Imperfection, ...] = (
    Imperfection(
        "pan_error", "camera.pan_error", "deg", "the mount reports pan + pan_error",
        "angle", bound=10.0,
        columns=_plain("pan_error", "bench_pan_error_deg", "deg", "pan error"),
        features=_linear("pan_error_deg", "bench_pan_error_deg", "pan error (deg)"),
        stage="record"),
    Imperfection(
        "pitch", "camera.pitch", "deg", "the optical axis raised from level", "angle",
        bound=20.0, columns=_plain("pitch", "bench_pitch_deg", "deg", "camera pitch"),
        features=_linear("pitch_deg", "bench_pitch_deg", "camera pitch (deg)")),
    Imperfection(
        "roll", "camera.roll", "deg", "clockwise as seen from behind the camera", "angle",
        bound=30.0, columns=_plain("roll", "bench_roll_deg", "deg", "camera roll"),
        features=_linear("roll_deg", "bench_roll_deg", "camera roll (deg)")),
    Imperfection(
        "distortion", "camera.distortion", "1", "Brown–Conrady lens distortion [k1, k2]",
        "lens", low=-1.0, high=1.0,
        columns=(Column("bench_k1", "1", "lens k1", lambda s: s.bench.distortion[0]),
                 Column("bench_k2", "1", "lens k2", lambda s: s.bench.distortion[1])),
        # an unknown lens's k1 moves an image at off-axis angle φ by ∝ k1·tan³φ and scales
        # it by ∝ k1·tan²φ
        features=(Feature("k1_tan3", "k1·tan³(off-axis) of an uncorrected lens",
                          lambda col, obj: _unknown_k1(col) * _off_axis_tan(obj) ** 3),
                  Feature("k1_tan2", "k1·tan²(off-axis) of an uncorrected lens",
                          lambda col, obj: _unknown_k1(col) * _off_axis_tan(obj) ** 2))),
    Imperfection(
        "distortion_known", "camera.distortion_known", "bool",
        "the capture record holds the lens's coefficients (the detector undistorts)", "flag",
        source=False, stage="record",
        columns=_plain("distortion_known", "bench_distortion_known", "bool",
                       "lens coefficients in the capture record")),
    Imperfection(
        "noise", "camera.noise", "electrons", "Poisson shot noise (full_well electrons at "
        "radiance 1) plus Gaussian read noise", "noise",
        columns=(Column("bench_full_well", "e-", "full well (0: no sensor noise)",
                        lambda s: s.bench.noise.full_well if s.bench.noise else 0.0),
                 Column("bench_read_noise", "e-", "read noise rms",
                        lambda s: s.bench.noise.read_noise if s.bench.noise else 0.0)),
        # shot noise goes as 1/√full_well
        features=(Feature("shot_noise", "1/√full_well",
                          lambda col, _obj: _where_noise(col, lambda fw: 1.0 / np.sqrt(fw))),
                  Feature("read_noise_rel", "read noise / full well",
                          lambda col, _obj: _where_noise(
                              col, lambda fw: col("bench_read_noise") / fw))),
        stage="sensor"),
    Imperfection(
        "jpeg_quality", "camera.jpeg_quality", "1", "the frame stored as JPEG at this quality",
        "quality", low=1, high=100,
        columns=(Column("bench_jpeg_quality", "1", "JPEG quality (0: lossless PNG)",
                        lambda s: s.bench.jpeg_quality or 0),),
        features=(Feature("jpeg_loss", "(100 − quality)/100",
                          lambda col, _obj: np.where(col("bench_jpeg_quality") > 0,
                                                   (100.0 - col("bench_jpeg_quality")) / 100,
                                                   0.0)),),
        stage="sensor"),
    Imperfection(
        "curvature_radius", "mirror.curvature_radius", "cm",
        "a spherical mirror of this radius (> 0 concave); |radius| ≥ the mirror's diagonal",
        "radius", spec_key="mirror.curvature",
        columns=(Column("bench_curvature_per_cm", "1/cm", "1/radius (0: flat)",
                        lambda s: 1.0 / s.bench.curvature_radius
                        if s.bench.curvature_radius else 0.0),),
        features=(Feature("mirror_power", "2·cos i·d1·d2/(R·d_total)", _mirror_power),)),
    Imperfection(
        "tilt", "mirror.tilt", "deg", "the mirror's top leans away from the camera", "angle",
        bound=45.0, columns=_plain("tilt", "bench_tilt_deg", "deg", "mirror tilt"),
        features=_linear("tilt_deg", "bench_tilt_deg", "mirror tilt (deg)")),
    Imperfection(
        "calibration_distance_error", "calibration.distance_error", "cm",
        "the calibration's reference stands at 100 + this, 100 assumed", "number",
        low=-50.0, high=100.0, why="the reference must stand between 50 and 200 cm",
        columns=_plain("calibration_distance_error", "bench_calibration_error_cm", "cm",
                       "calibration reference's distance error"),
        features=_linear("calibration_error_cm", "bench_calibration_error_cm",
                         "calibration distance error (cm)"),
        stage="record"),
    Imperfection(
        "known_position", "beacons.known_position", "cm",
        "where the experimenter believes a beacon stands", "offset",
        spec_key="beacon.known_position_offset",
        columns=(Column("bench_beacon_dx_cm", "cm", "believed − true x of beacon 0",
                        lambda s: _beacon_offset(s, 0)),
                 Column("bench_beacon_dy_cm", "cm", "believed − true y of beacon 0",
                        lambda s: _beacon_offset(s, 1))),
        stage="record"),
)
# Bench field → the key path a scene file writes it under (the budget's sources)
KEYS = {imp.field: imp.key for imp in REGISTRY if imp.source and imp.block != "beacons"}
# a dataset row's imperfection columns (every row has all of them, ideal values on an
# ideal bench, so that tables of different specs share a schema)
ROW_COLUMNS = tuple(c.name for imp in REGISTRY for c in imp.columns)
# the error model's bench features, each linear in its imperfection's first-order effect
FEATURES = tuple(f for imp in REGISTRY for f in imp.features)
_IDEAL = Bench()


@dataclass(frozen=True)
class Source:
    """One imperfection of a scene: its key path and its value as written."""

    key: str
    value: Any


def sources(scene: Scene) -> list[Source]:
    """The imperfections present in ``scene``, in docs/scenes.md's order.

    ``camera.distortion_known`` is not a source of its own: it says whether the
    ``camera.distortion`` source is corrected by the detector.
    """
    out = []
    for f in fields(Bench):
        if f.name in KEYS and getattr(scene.bench, f.name) != getattr(_IDEAL, f.name):
            value = getattr(scene.bench, f.name)
            if f.name == "noise":
                value = {"full_well": value.full_well, "read_noise": value.read_noise}
            out.append(Source(KEYS[f.name], list(value) if isinstance(value, tuple) else value))
    for i, b in enumerate(scene.beacons):
        if b.known_position is not None and tuple(b.known_position) != tuple(b.position):
            out.append(Source(f"beacons[{i}].known_position", list(b.known_position)))
    return out


def as_keys(scene: Scene) -> dict[str, Any]:
    """The scene's imperfections as a scene file writes them, by key path (with
    ``camera.distortion_known`` where it is false); empty for an ideal bench."""
    found = {s.key: s.value for s in sources(scene)}
    if "camera.distortion" in found and not scene.bench.distortion_known:
        found["camera.distortion_known"] = False
    return found


def ideal(scene: Scene) -> Scene:
    """The same scene on an ideal bench."""
    return replace(scene, bench=Bench(),
                   beacons=tuple(replace(b, known_position=None) for b in scene.beacons))


def optics_of(scene: Scene) -> Scene:
    """What Mitsuba renders of ``scene``: the scene with its ``sensor`` and ``record``
    imperfections made ideal (those act after the render or only on beliefs)."""
    after = {imp.field for imp in REGISTRY if imp.stage != "optics"}
    kept = {f.name: getattr(_IDEAL, f.name) for f in fields(Bench) if f.name in after}
    beacons = scene.beacons
    if "known_position" in after:
        beacons = tuple(replace(b, known_position=None) for b in beacons)
    return replace(scene, bench=replace(scene.bench, **kept), beacons=beacons)


def only(scene: Scene, key: str) -> Scene:
    """The scene on an ideal bench but for the one source ``key`` (as :func:`sources`
    names it)."""
    base = ideal(scene)
    if key.startswith("beacons["):
        i = int(key[len("beacons["):key.index("]")])
        beacons = list(base.beacons)
        beacons[i] = scene.beacons[i]
        return replace(base, beacons=tuple(beacons))
    name = next(n for n, k in KEYS.items() if k == key)
    kept = {name: getattr(scene.bench, name)}
    if name == "distortion":
        kept["distortion_known"] = scene.bench.distortion_known
    return replace(base, bench=replace(Bench(), **kept))


def row_values(scene: Scene) -> dict[str, Any]:
    """The scene's imperfections as a dataset row's columns (:data:`ROW_COLUMNS`)."""
    return {c.name: c.of(scene) for imp in REGISTRY for c in imp.columns}


def judged_values(scene: Scene) -> dict[str, float]:
    """The imperfections present in ``scene`` (:func:`sources`), each as the number its
    size is judged by, keyed as a dataset spec's ``bench`` block draws it (the mirror's
    curvature 1/R, a beacon's offset from its believed position, a lens's k1 and k2, a
    sensor's full well and read noise): what an error model's bench domain is checked
    against."""
    out: dict[str, float] = {}
    bench = scene.bench
    for src in sources(scene):
        if src.key.startswith("beacons["):
            b = scene.beacons[int(src.key[len("beacons["):src.key.index("]")])]
            offset = max(abs(p - q) for p, q in zip(b.believed, b.position, strict=True))
            key = _BY_FIELD["known_position"].spec_path
            out[key] = max(out.get(key, 0.0), offset)
            continue
        imp = next(i for i in REGISTRY if i.key == src.key)
        if imp.form == "lens":
            out[f"{imp.spec_path}[0]"], out[f"{imp.spec_path}[1]"] = bench.distortion
        elif imp.form == "noise":
            out[f"{imp.spec_path}.full_well"] = bench.noise.full_well
            out[f"{imp.spec_path}.read_noise"] = bench.noise.read_noise
        elif imp.form == "radius":
            out[imp.spec_path] = 1.0 / bench.curvature_radius
        else:
            out[imp.spec_path] = float(src.value)
    return out


def spec_ranges(bench: dict) -> dict[str, tuple[float, float]]:
    """A dataset spec's ``bench`` block as (low, high) per key of
    :func:`judged_values` (a value v is (v, v); a beacon offset's range is judged by its
    largest |offset|, from 0; a flag has no range)."""
    out: dict[str, tuple[float, float]] = {}

    def span(raw: Any) -> tuple[float, float]:
        lo, hi = (raw[0], raw[1]) if isinstance(raw, list) else (raw, raw)
        return float(lo), float(hi)

    for block, keys in (bench or {}).items():
        for key, raw in (keys or {}).items():
            imp = next((i for i in REGISTRY if i.spec_path == f"{block}.{key}"), None)
            if imp is None or imp.form == "flag":
                continue
            path = imp.spec_path
            if imp.form == "lens":
                for j in (0, 1):
                    out[f"{path}[{j}]"] = span(raw[j])
            elif imp.form == "noise":
                for k in ("full_well", "read_noise"):
                    out[f"{path}.{k}"] = span(raw[k])
            elif imp.form == "offset":
                out[path] = (0.0, max(abs(x) for x in span(raw)))
            else:
                out[path] = span(raw)
    return out


_BY_FIELD = {imp.field: imp for imp in REGISTRY}
