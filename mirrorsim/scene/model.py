"""The scene as data: complete, immutable, no I/O.

A :class:`Scene` from an entry point (:mod:`mirrorsim.pipelines.scenes`) is whole: the
camera's resolved pan and the target's facing are computed from the geometry by
:func:`mirrorsim.truth.compose.compose_scene`.  Only the scene reader's own output,
before it is composed, leaves them NaN.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from mirrorsim.errors import BadParameter
from mirrorsim.scene import values
from mirrorsim.scene.render_settings import RenderSettings
from solver.geometry import line_normal, signed_distance, unit

# Physical dimensions of the rendered objects that the scene file does not set (cm).
# They enter the overlap checks, so they live with the model rather than the renderer.
MIRROR_DEPTH = 0.6  # glass + dark backing + frame, behind the reflective plane
MIRROR_FRAME = 0.5  # frame width on the sides and top, outside the reflective area
# how far the frame's front stands before the glass's rim: a ray leaving the glass at a
# slant meets the frame's inner side within MIRROR_LIP·tan(incidence) of the edge, so
# the frame hides that strip of the reflection (visibility.visibility counts it)
MIRROR_LIP = 0.05
TARGET_THICKNESS = 0.4
# Documented bounds on a scene's sizes, so that every scene `check` accepts renders:
# the pegboard's texture has 24 texels a cm (a 200 cm board: 4800² texels, ~0.3 GiB);
# no size or height on the bench (mirror, target, pencil, occluder, camera) exceeds it
MAX_BOARD_CM = 200.0
MAX_HFOV_DEG = 170.0  # a pinhole camera's widest field of view that a file may give
MAX_RESOLUTION = (7680, 4320)  # 8K UHD: the film and its passes fit a few GiB
# electrons: at 1e7 shot noise is 0.03 % of full scale (no noise: leave `noise` out)
MAX_FULL_WELL = 1e7
MAX_READ_NOISE = 1e5  # electrons rms
# a mirror flatter than this (100 km) is flat: leave `curvature_radius` out
MAX_CURVATURE_RADIUS = 1e7
PENCIL_RADIUS = 0.4  # circumradius of the hexagonal pencil (0.69 cm across flats)
# The measured edges belong to the face nearest the camera: the panel's front (half its
# thickness before its centre), the pencil's near side.  Size constancy holds for that
# face's depth.  The pencil's top and foot are measured on the middle 60 % of its
# silhouette's columns, where the hexagon's near side lies 0.336–0.341 cm before the
# axis whatever the pencil's turn (0.338 on average: numerically, over turns 0–60°).  A
# flat's 0.346 and a corner's 0.4 bound it; their mean, 0.373, would put every pencil
# 0.035 cm too near (0.05 % at 70 cm, not cancelled by the calibration at 1 m).
FRONT_OFFSET = {"target": TARGET_THICKNESS / 2, "beacon": 0.338 * PENCIL_RADIUS / 0.4}
OCCLUDER_THICKNESS = 1.0
# The detector tells a pencil's direct view (within MISPLACED_DISTANCE of its beacon's
# own distance) from its reflection (2·depth·cos i farther: REFLECTION_EXCESS and more 4 cm
# before the glass, where plan places beacons); `check` warns where a scene asks more.  A
# bench reads distances up to BENCH_SCALE_TOLERANCE off (the bench model's calibration).
MISPLACED_DISTANCE, REFLECTION_EXCESS, BENCH_SCALE_TOLERANCE = 0.02, 0.05, 0.03
# 3-D scenes (docs/scenes.md): a raised object stands on a post of this radius (thinner
# than the pencil, so it neither hides the object nor is taken for it), of STAND colour;
# a mirror may lean by at most MAX_LEAN_DEG (a lab mirror leans a degree or two; beyond
# 10° its images leave the frame's rows the detector searches)
STAND_RADIUS, MAX_LEAN_DEG = 0.15, 10.0
PAN_WORDS = ("mirror", "target", "beacon")

Point2 = tuple[float, float]


@dataclass(frozen=True)
class Board:
    """The pegboard: ``size`` (cm) and its hole grid (``hole_pitch`` 0 = plain)."""

    size: Point2
    hole_pitch: float = 2.5
    hole_diameter: float = 0.6

    def __post_init__(self):
        values.pair("size", self.size, positive=True)
        values.number("hole_pitch", self.hole_pitch, low=0.0)
        values.number("hole_diameter", self.hole_diameter, positive=True)
        if 0.0 < self.hole_pitch <= self.hole_diameter:
            raise BadParameter("hole_pitch", f"{self.hole_pitch:g} must exceed the hole "
                               f"diameter {self.hole_diameter:g} cm (or be 0 for a plain board)")

    def hole_centres(self) -> np.ndarray:
        """(k, 2) centres of the holes (cm), as the rendered pegboard has them: every whole
        multiple of the pitch inside the board, in x from the near edge (x = 0) and in y
        from the far edge (y = size[1]), where the texture's rows start; none on a plain
        board."""
        if self.hole_pitch <= 0:
            return np.zeros((0, 2))
        xs, ys = (np.arange(1, math.ceil(s / self.hole_pitch)) * self.hole_pitch
                  for s in self.size)
        xs, ys = xs[xs < self.size[0]], ys[ys < self.size[1]]
        gx, gy = np.meshgrid(xs, self.size[1] - ys)
        return np.column_stack([gx.ravel(), gy.ravel()])


@dataclass(frozen=True)
class Camera:
    """A level pinhole camera; ``pan`` as written, ``pan_deg`` the resolved bearing."""

    position: Point2
    height: float
    resolution: tuple[int, int]
    hfov: float
    pan: float | str
    pan_deg: float

    def __post_init__(self):
        values.pair("position", self.position)
        values.number("height", self.height, positive=True)
        values.resolution("resolution", self.resolution)
        if not 0.0 < values.number("hfov", self.hfov) < 180.0:
            raise BadParameter("hfov", f"{self.hfov:g} must be within (0, 180)° (a pinhole)")
        if not (isinstance(self.pan, str) and self.pan in PAN_WORDS):
            if isinstance(self.pan, str):
                raise BadParameter("pan", f"{self.pan!r}: expected a bearing in degrees or "
                                   f"one of {', '.join(PAN_WORDS)}")
            values.number("pan", self.pan)

    @property
    def width(self) -> int:
        """Image width in px."""
        return self.resolution[0]

    @property
    def height_px(self) -> int:
        """Image height in px."""
        return self.resolution[1]

    @property
    def fx(self) -> float:
        """Focal length in px (:func:`fx_of`); square pixels, so fy = fx."""
        return fx_of(self.width, self.hfov)

    @property
    def cx(self) -> float:
        """Principal point's column, OpenCV convention (pixel centres at integers)."""
        return self.width / 2.0 - 0.5

    @property
    def cy(self) -> float:
        """Principal point's row."""
        return self.height_px / 2.0 - 0.5

    @property
    def center3(self) -> np.ndarray:
        """Optical centre in 3-D."""
        return np.array([self.position[0], self.position[1], self.height])


@dataclass(frozen=True)
class Mirror:
    """A rectangle standing on the board, its bottom edge along ``yaw``: upright, or
    leaning by ``lean`` (deg; its top tipped away from its reflective face, a turn about
    its bottom edge), that edge ``z`` cm above the board (on a stand)."""

    center: Point2
    yaw: float
    size: Point2  # width along the surface line, height
    lean: float = 0.0
    z: float = 0.0

    def __post_init__(self):
        values.pair("center", self.center)
        values.number("yaw", self.yaw)
        values.pair("size", self.size, positive=True)
        values.number("lean", self.lean, low=-MAX_LEAN_DEG, high=MAX_LEAN_DEG)
        values.number("z", self.z, low=0.0)

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """The two ends of the reflective bottom edge."""
        c, d = np.asarray(self.center, float), unit(self.yaw) * self.size[0] / 2.0
        return c - d, c + d

    def normal_towards(self, point: ArrayLike) -> np.ndarray:
        """Unit normal of the mirror's line on the side of ``point`` (2-D)."""
        n = line_normal(self.yaw)
        return n if signed_distance(point, self.center, self.yaw) >= 0 else -n


@dataclass(frozen=True)
class Target:
    """An upright panel (width, height) whose face turns to ``facing_deg``."""

    position: Point2
    size: Point2
    facing_deg: float
    z: float = 0.0  # its bottom edge above the board (cm): on a stand

    def __post_init__(self):  # (the facing is the composer's: NaN until composed)
        values.pair("position", self.position)
        values.pair("size", self.size, positive=True)
        values.number("z", self.z, low=0.0)

    @property
    def base3(self) -> np.ndarray:
        """The middle of its bottom edge in 3-D (cm)."""
        return np.array([self.position[0], self.position[1], self.z])

    @property
    def height(self) -> float:
        """Panel height (cm)."""
        return self.size[1]

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """Ends of the panel's footprint (its width runs across the facing direction)."""
        p, d = np.asarray(self.position, float), unit(self.facing_deg + 90.0) * self.size[0] / 2
        return p - d, p + d


def pencil_paint_height(height: float) -> float:
    """Height of a pencil's painted band, below its sharpened cone (cm)."""
    return height - min(1.2, 0.35 * height)


def pencil_cone_ratio(height: float) -> float:
    """A pencil's sharpened cone's height over its painted band's."""
    paint = pencil_paint_height(height)
    return (height - paint) / paint


@dataclass(frozen=True)
class Beacon:
    """An upright pencil: its axis over ``position``, ``height`` above the board;
    ``known_position`` is where the experimenter believes it stands (None: where it is)."""

    position: Point2
    height: float
    known_position: Point2 | None = None
    z: float = 0.0  # its foot above the board (cm): on a stand

    def __post_init__(self):
        values.pair("position", self.position)
        values.number("height", self.height, positive=True)
        if self.known_position is not None:
            values.pair("known_position", self.known_position)
        values.number("z", self.z, low=0.0)

    @property
    def base3(self) -> np.ndarray:
        """Its foot on its axis in 3-D (cm)."""
        return np.array([self.position[0], self.position[1], self.z])

    @property
    def believed(self) -> Point2:
        """Where the experimenter believes the pencil stands."""
        return self.position if self.known_position is None else self.known_position


@dataclass(frozen=True)
class Occluder:
    """An upright wall from ``start`` to ``end``."""

    start: Point2
    end: Point2
    height: float

    def __post_init__(self):
        start, end = values.pair("start", self.start), values.pair("end", self.end)
        values.number("height", self.height, positive=True)
        if math.hypot(end[0] - start[0], end[1] - start[1]) < 0.1:
            raise BadParameter("end", f"{list(self.end)}: the wall has no length")


def fx_of(width: float, hfov_deg: float) -> float:
    """A pinhole's focal length in px for a frame ``width`` px wide seeing ``hfov_deg``:
    (W/2)/tan(hfov/2) (square pixels, so fy = fx)."""
    return (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


@dataclass(frozen=True)
class SensorNoise:
    """Sensor noise in electrons: the exposure puts ``full_well`` electrons at linear
    radiance 1; Poisson shot noise plus Gaussian read noise of ``read_noise`` rms."""

    full_well: float
    read_noise: float

    def __post_init__(self):
        values.number("full_well", self.full_well, positive=True)
        values.number("read_noise", self.read_noise, low=0.0)


@dataclass(frozen=True)
class Bench:
    """The imperfections of a real bench (docs/scenes.md *Bench imperfections*); the
    defaults are the ideal bench.  The beacons' believed positions live on
    :class:`Beacon`.  None of this reaches :mod:`mirrorsim.truth.optics`' truth: it changes
    what is rendered, or what the capture record says, or the calibration."""

    pan_error: float = 0.0  # deg: the mount reports pan + pan_error
    pitch: float = 0.0  # deg: optical axis raised from level
    roll: float = 0.0  # deg: clockwise as seen from behind the camera
    distortion: tuple[float, float] = (0.0, 0.0)  # Brown–Conrady k1, k2
    distortion_known: bool = True  # the capture record holds the coefficients
    noise: SensorNoise | None = None
    jpeg_quality: int | None = None  # None: lossless PNG
    curvature_radius: float | None = None  # cm; > 0 concave, None: flat
    tilt: float = 0.0  # deg: the mirror's top leans away from the camera
    calibration_distance_error: float = 0.0  # cm: reference at 100 + this, 100 assumed


# a scene's name names its files: letters, digits, '.', '_', '-', no path; a scene file
# names at most 64 characters, the frames derived from it add their suffixes (_b0,
# _pose000, _fixed0) to that
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
NAME_RULE = "letters, digits, '.', '_', '-'; no path; at most 64 characters"
_DERIVED_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")


@dataclass(frozen=True)
class Scene:
    """A validated scene.  Build one with :func:`mirrorsim.pipelines.scenes.load_scene`."""

    name: str
    board: Board
    camera: Camera
    mirror: Mirror
    target: Target
    beacons: tuple[Beacon, ...]
    occluders: tuple[Occluder, ...] = ()
    render: RenderSettings = field(default_factory=RenderSettings)
    bench: Bench = field(default_factory=Bench)
    source: str = "<scene>"
    warnings: tuple[str, ...] = ()

    def __post_init__(self):
        # every file of a scene is named after it: a name edited in by a script
        # (dataclasses.replace) is held to the scene reader's rule, or a parent path would write
        # outside the run's folder
        if not isinstance(self.name, str) or not _DERIVED_NAME.fullmatch(self.name):
            raise BadParameter("scene.name", f"{self.name!r} is not a plain file name "
                               f"({NAME_RULE})")
        if not self.beacons:  # the pan, the truth and the solve each need one
            raise BadParameter("scene.beacons", "expected at least one beacon")

    def raised(self, bkey: Callable[[int], str] | None = None) -> list[tuple[str, float]]:
        """What takes the scene off the board's plane, as (key path, value) where it
        is not 0: the mirror's lean, the raised mirror's, target's and pencils' heights
        (``bkey(i)``: how the file names beacon ``i``)."""
        if bkey is None:
            bkey = (lambda i: f"beacons[{i}]") if len(self.beacons) > 1 else (lambda _i: "beacon")
        m = self.mirror
        return [(k, v) for k, v in (
            ("mirror.lean", m.lean), ("mirror.center[2]", m.z),
            ("target.position[2]", self.target.z),
            *((f"{bkey(i)}.position[2]", b.z) for i, b in enumerate(self.beacons))) if v]

    @property
    def is_3d(self) -> bool:
        """Whether anything leaves the board's plane: a raised object or mirror, or a
        leaning mirror (the 3-D solve is then the default, docs/method.md)."""
        return bool(self.raised())

    def with_render(self, **settings) -> Scene:
        """The same scene rendered with other settings (``spp``, ``seed``, ``sampler``…),
        checked as every :class:`RenderSettings` is."""
        return replace(self, render=replace(self.render, **settings))


def check_is_scene(value: object) -> None:
    """Refuse a value given as a scene that is not a :class:`Scene` (a path, a dict), in
    one line rather than an AttributeError deep in the code."""
    if not isinstance(value, Scene):
        raise BadParameter("scene", f"expected a Scene (mirrorsim.load_scene), not "
                           f"{type(value).__name__}")


def footprints(scene: Scene, bkey: Callable[[int], str] | None = None
               ) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """Each object's footprint as a capsule: (key, segment start, segment end, radius).

    ``bkey(i)`` names beacon i's key as the file wrote it (``beacon`` or ``beacons[i]``).
    """
    if bkey is None:
        bkey = (lambda i: f"beacons[{i}]") if len(scene.beacons) > 1 else (lambda _i: "beacon")
    out = [("mirror.center", *scene.mirror.ends(), MIRROR_DEPTH),
           ("target.position", *scene.target.ends(), TARGET_THICKNESS / 2)]
    for i, b in enumerate(scene.beacons):
        p = np.asarray(b.position, float)
        out.append((f"{bkey(i)}.position", p, p, PENCIL_RADIUS))
    for i, o in enumerate(scene.occluders):
        out.append((f"occluders[{i}]", np.asarray(o.start, float), np.asarray(o.end, float),
                    OCCLUDER_THICKNESS / 2))
    return out


def beacon_frame_name(scene_name: str, i: int) -> str:
    """The name of the frame of a scene of several beacons that holds beacon i alone."""
    return f"{scene_name}_b{i}"


def frame_beacon(scene_name: str, frame: str) -> int | None:
    """Which of its scene's beacons a frame named by :func:`beacon_frame_name` holds
    (None: the scene's one frame)."""
    k = frame.removeprefix(f"{scene_name}_b")
    return int(k) if k != frame and k.isdigit() else None
