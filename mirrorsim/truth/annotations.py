"""A frame's annotations for learning pipelines, from the exact geometry and the id pass.

For each object (the target, each beacon, the mirror's glass) and each view of it
(``direct``, and ``mirror``: its image in the glass), an *instance*: its mask (the id
pass's pixels, as COCO's compressed RLE), its box and area, and its keypoints (a pencil's
tip and foot, the corners of the target's face towards the mirror and of the glass)
projected exactly: a point in the mirror is the point reflected in the glass's plane as
the bench stands it (its lean and tilt), then the camera as it stands (pitch, roll) and
its lens's distortion.  A curved glass images a point where no plane does: its
in-mirror keypoints are not labelled (visibility 0).  Beside them, the mirror's
*virtual camera*: the camera reflected in the glass's plane (a curved glass's tangent
plane at its centre), whose projection of a point is where a flat glass shows it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from mirrorsim.formats import rle
from mirrorsim.scene.model import TARGET_THICKNESS, Scene
from mirrorsim.scene.projection import camera_axes, distort_pixels, project, radial_slope
from mirrorsim.truth.visibility import glass_frame, sag
from solver.geometry import unit

VIEWS = ("direct", "mirror")
# COCO's visibility flags: 0 off the film (or behind the camera), 1 on it but hidden
# (behind something, or outside the glass), 2 seen
OFF, HIDDEN, SEEN = 0, 1, 2
# a keypoint is seen where its object's mask reaches within this many pixels of it: a
# pencil's graphite cone is 0.8 px across 2 px below its point at full size
SEEN_WITHIN_PX = 2
CORNERS = ("top_left", "top_right", "bottom_right", "bottom_left")


@dataclass(frozen=True)
class Category:
    """An annotation category: an object seen one way, and the names of its keypoints
    (with COCO's skeleton: pairs of 1-based keypoint indices)."""

    name: str
    keypoints: tuple[str, ...]
    skeleton: tuple[tuple[int, int], ...]


_PENCIL = (("tip", "foot"), ((1, 2),))
_QUAD = (CORNERS, ((1, 2), (2, 3), (3, 4), (4, 1)))
# every category a dataset's COCO file declares, in its ids' order (1-based there)
CATEGORIES = (Category("target_in_mirror", *_QUAD), Category("beacon_in_mirror", *_PENCIL),
              Category("target_direct", *_QUAD), Category("beacon_direct", *_PENCIL),
              Category("mirror", *_QUAD))


def category_of(obj: str, view: str) -> Category:
    """The category of object ``obj`` (``target``, ``beacons[i]``, ``mirror``) seen in
    ``view``."""
    kind = "beacon" if obj.startswith("beacons") else obj
    name = "mirror" if kind == "mirror" else f"{kind}_{'in_mirror' if view == 'mirror' else view}"
    return next(c for c in CATEGORIES if c.name == name)


@dataclass(frozen=True)
class Keypoint:
    """A keypoint's pixel (OpenCV's convention: pixel centres at integers) and whether
    it is seen (:data:`SEEN`), on the film but hidden (:data:`HIDDEN`) or off it
    (:data:`OFF`)."""

    name: str
    u: float
    v: float
    visible: int


@dataclass(frozen=True)
class Instance:
    """One object seen one way: its mask (COCO compressed RLE), its box (x, y, width,
    height: the mask's pixels, inclusive) and area (pixels), and its keypoints."""

    object: str
    view: str
    category: str
    bbox: tuple[int, int, int, int]
    area: int
    mask: dict
    keypoints: tuple[Keypoint, ...]

    def to_json(self) -> dict:
        """docs/files.md's ``annotations.instances[i]``."""
        return {"object": self.object, "view": self.view, "category": self.category,
                "bbox": list(self.bbox), "area": self.area, "mask": dict(self.mask),
                "keypoints": [{"name": k.name, "u": k.u, "v": k.v, "visible": k.visible}
                              for k in self.keypoints]}

    @classmethod
    def from_json(cls, d: dict) -> Instance:
        """Inverse of :meth:`to_json`."""
        return cls(d["object"], d["view"], d["category"], tuple(d["bbox"]), d["area"],
                   dict(d["mask"]), tuple(Keypoint(k["name"], k["u"], k["v"], k["visible"])
                                          for k in d["keypoints"]))


@dataclass(frozen=True)
class VirtualCamera:
    """The camera reflected in the glass's plane: ``world_to_camera`` (4×4, cm; OpenCV's
    axes: x right, y down, z forward) maps a point X to where the real camera sees X's
    reflection, so that ``intrinsics`` @ (its first three rows @ [X, 1]) is that
    reflection's pixel (before the lens's ``distortion`` k1, k2).  Its rotation is a
    reflection (determinant −1): a mirror's view is mirrored.  ``position`` is its
    centre (cm)."""

    position: tuple[float, float, float]
    world_to_camera: tuple[tuple[float, ...], ...]
    intrinsics: tuple[tuple[float, ...], ...]
    distortion: tuple[float, float]

    def to_json(self) -> dict:
        """docs/files.md's ``annotations.virtual_camera``."""
        return {"position": list(self.position),
                "world_to_camera": [list(r) for r in self.world_to_camera],
                "intrinsics": [list(r) for r in self.intrinsics],
                "distortion": list(self.distortion)}

    @classmethod
    def from_json(cls, d: dict) -> VirtualCamera:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(d["position"]), tuple(tuple(r) for r in d["world_to_camera"]),
                   tuple(tuple(r) for r in d["intrinsics"]), tuple(d["distortion"]))


@dataclass(frozen=True)
class Annotations:
    """A frame's annotations: its size, its instances and the mirror's virtual camera."""

    width: int
    height: int
    instances: tuple[Instance, ...]
    virtual_camera: VirtualCamera

    def to_json(self) -> dict:
        """docs/files.md's ``annotations``."""
        return {"width": self.width, "height": self.height,
                "instances": [i.to_json() for i in self.instances],
                "virtual_camera": self.virtual_camera.to_json()}

    @classmethod
    def from_json(cls, d: dict) -> Annotations:
        """Inverse of :meth:`to_json`."""
        return cls(d["width"], d["height"], tuple(Instance.from_json(i) for i in d["instances"]),
                   VirtualCamera.from_json(d["virtual_camera"]))


def keypoints3(scene: Scene) -> dict[str, np.ndarray]:
    """Each object's keypoints in 3-D (cm), in its category's order: a pencil's tip and
    foot on its axis; the corners of the target's face towards ``facing_deg``; the
    glass's corners as the bench stands it."""
    t = scene.target
    f, a = unit(t.facing_deg), unit(t.facing_deg + 90.0)  # a: right, looking at the face
    face = np.asarray(t.position, float) + f * TARGET_THICKNESS / 2
    w, h = t.size

    def corners(centre, right, up, half_w, half_h) -> np.ndarray:
        return np.array([centre + s * right * half_w + e * up * half_h
                         for s, e in ((-1, 1), (1, 1), (1, -1), (-1, -1))])

    up = np.array([0.0, 0.0, 1.0])
    out = {"target": corners(np.r_[face, t.z + h / 2], np.r_[a, 0.0], up, w / 2, h / 2)}
    for i, b in enumerate(scene.beacons):
        out[f"beacons[{i}]"] = np.array([[*b.position, b.z + b.height], [*b.position, b.z]])
    g, along, gup, n = glass_frame(scene)
    w2, h2 = scene.mirror.size[0] / 2, scene.mirror.size[1] / 2
    # a curved glass's rim stands off its tangent plane by the sag at each corner
    rim = sag(np.array([-w2, w2, w2, -w2]), np.array([h2, h2, -h2, -h2]),
              scene.bench.curvature_radius)
    out["mirror"] = corners(g, along, gup, w2, h2) + np.outer(rim, n)
    return out


def reflect(scene: Scene, points: np.ndarray) -> np.ndarray:
    """Points reflected in the glass's plane as the bench stands it."""
    g, _, _, n = glass_frame(scene)
    p = np.asarray(points, float)
    return p - 2.0 * np.outer((p - g) @ n, n)


def pixels(scene: Scene, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the camera as it stands (pitch, roll, lens) images 3-D points: u, v and
    depth (negative behind it)."""
    bench = scene.bench
    u, v, depth = project(scene.camera, points, bench.pitch, roll=bench.roll)
    if bench.distortion != (0.0, 0.0):
        u, v = distort_pixels(scene.camera, u, v, k=bench.distortion)
    return u, v, depth


def _on_the_lens(scene: Scene, points: np.ndarray) -> np.ndarray:
    """Whether the lens images each point where its radial map still grows (a barrel
    lens folds points far off its axis back onto the frame: those are off it)."""
    k = scene.bench.distortion
    forward, right, down = camera_axes(scene.camera, scene.bench.pitch, scene.bench.roll)
    p = np.asarray(points, float) - scene.camera.center3
    z = p @ forward
    with np.errstate(divide="ignore", invalid="ignore"):
        r2 = ((p @ right) ** 2 + (p @ down) ** 2) / z**2
    return (z > 0) & (radial_slope(r2, k) > 0)


def virtual_camera(scene: Scene) -> VirtualCamera:
    """The mirror's virtual camera (:class:`VirtualCamera`)."""
    cam, bench = scene.camera, scene.bench
    forward, right, down = camera_axes(cam, bench.pitch, bench.roll)
    rot = np.array([right, down, forward])
    extrinsic = np.eye(4)
    extrinsic[:3, :3], extrinsic[:3, 3] = rot, -rot @ cam.center3
    g, _, _, n = glass_frame(scene)
    mirror = np.eye(4)
    mirror[:3, :3] = np.eye(3) - 2.0 * np.outer(n, n)
    mirror[:3, 3] = 2.0 * (n @ g) * n
    k = ((cam.fx, 0.0, cam.cx), (0.0, cam.fx, cam.cy), (0.0, 0.0, 1.0))
    return VirtualCamera(tuple(float(c) for c in reflect(scene, cam.center3[None])[0]),
                         tuple(tuple(float(c) for c in r) for r in extrinsic @ mirror),
                         k, tuple(float(c) for c in bench.distortion))


def frame_annotations(scene: Scene, first: np.ndarray, in_mirror: np.ndarray, *,
                      labels: Mapping[str, int]) -> Annotations:
    """The frame's annotations from its id pass (``first``: the surface each pixel
    centre sees; ``in_mirror``: what the glass shows there) and each object's label
    there (``labels``: ``target``, ``beacons[i]``, ``mirror``).  An object seen no way
    has no instance."""
    points = keypoints3(scene)
    out = []
    for obj, label in labels.items():
        for view, ids in (("direct", first), ("mirror", in_mirror)):
            if obj == "mirror" and view == "mirror":
                continue
            mask = ids == label
            if not mask.any():
                continue
            pts = reflect(scene, points[obj]) if view == "mirror" else points[obj]
            cat = category_of(obj, view)
            if view == "mirror" and scene.bench.curvature_radius is not None:
                # a curved glass images a point where no plane does: not labelled
                kps = tuple(Keypoint(name, 0.0, 0.0, OFF) for name in cat.keypoints)
            else:
                kps = _keypoints(scene, pts, mask, names=cat.keypoints)
            cols, rows = np.flatnonzero(mask.any(axis=0)), np.flatnonzero(mask.any(axis=1))
            bbox = (int(cols[0]), int(rows[0]), int(cols[-1] - cols[0] + 1),
                    int(rows[-1] - rows[0] + 1))
            out.append(Instance(obj, view, cat.name, bbox, int(mask.sum()), rle.encode(mask),
                                kps))
    cam = scene.camera
    return Annotations(cam.width, cam.height_px, tuple(out), virtual_camera(scene))


def _keypoints(scene: Scene, pts: np.ndarray, mask: np.ndarray, *, names: tuple[str, ...]
               ) -> tuple[Keypoint, ...]:
    """Each point's pixel and flag: seen where the mask holds the object within
    :data:`SEEN_WITHIN_PX` of it (a pencil's point is thinner than a pixel: the pixel
    centres next to it may see the board)."""
    u, v, depth = pixels(scene, pts)
    h, w = mask.shape
    out = []
    for name, uu, vv, d, ok in zip(names, u, v, depth, _on_the_lens(scene, pts), strict=True):
        if d <= 0 or not ok or not (np.isfinite(uu) and np.isfinite(vv)) or not (
                -0.5 <= uu < w - 0.5 and -0.5 <= vv < h - 0.5):
            flag = OFF
        else:
            iu, iv = int(round(float(uu))), int(round(float(vv)))
            r = SEEN_WITHIN_PX
            near = mask[max(iv - r, 0):iv + r + 1, max(iu - r, 0):iu + r + 1]
            flag = SEEN if near.any() else HIDDEN
        out.append(Keypoint(name, round(float(uu), 4), round(float(vv), 4), flag))
    return tuple(out)
