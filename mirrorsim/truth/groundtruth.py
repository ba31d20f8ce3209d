"""The exact ground truth of a scene and its JSON (``render``'s ``<name>.json``).

Each class has one ``to_json`` (the documents of docs/files.md) and one ``from_json``.
Every consumer (the CLI's tables, the plots, the dataset's rows) reads attributes.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from mirrorsim.formats.cache import unseal
from mirrorsim.formats.files import read_regular_bytes
from mirrorsim.formats.reader import point_list
from mirrorsim.scene.imperfections import as_keys
from mirrorsim.scene.model import Camera, Mirror, Occluder, Point2, Scene, check_is_scene
from mirrorsim.truth import optics, visibility
from mirrorsim.truth.annotations import Annotations
from mirrorsim.truth.optics import ImagePx
from solver.geometry import wrap_yaw
from solver.lsq3 import Measurements3
from solver.measurements import BeaconMeasurement, Measurements


def _pt(v) -> Point2:
    return (float(v[0]), float(v[1]))


def _pts(v) -> tuple[float, ...]:
    """A point as its JSON gives it: two coordinates, or three in a 3-D scene."""
    return tuple(float(c) for c in v)


@dataclass(frozen=True)
class ObjectTruth:
    """The exact image of the target or a beacon; ``bbox_px``/``visible_px`` come from the
    renderer's id pass (``visible_px`` None: not rendered).  In a 3-D scene
    (:attr:`~mirrorsim.scene.model.Scene.is_3d`) the points have three coordinates (the
    object's base on its axis, its image and the reflection point), ``elevation_deg`` is
    the image's elevation and d_total the 3-D path's length; in a planar one, two
    coordinates and no elevation."""

    position: tuple[float, ...]
    virtual: tuple[float, ...]
    alpha_deg: float
    d_total: float
    d1: float
    d2: float
    reflection_point: tuple[float, ...]
    mirror_offset: float
    image_px: ImagePx
    visible_fraction: float
    clipped: bool
    size: Point2 | None = None  # the target's (width, height)
    facing_deg: float | None = None  # the target's
    height: float | None = None  # a beacon's
    bbox_px: tuple[int, int, int, int] | None = None
    visible_px: int | None = None
    elevation_deg: float | None = None  # a 3-D scene's

    def to_json(self) -> dict:
        """docs/files.md's ``target`` / ``beacons[i]`` entry."""
        out = {"position": list(self.position), "virtual": list(self.virtual),
               "alpha_deg": self.alpha_deg, "d_total": self.d_total, "d1": self.d1,
               "d2": self.d2, "reflection_point": list(self.reflection_point),
               "mirror_offset": self.mirror_offset,
               "image_px": {"u_axis": self.image_px.u_axis, "v_top": self.image_px.v_top,
                            "v_bottom": self.image_px.v_bottom,
                            "height": self.image_px.height},
               "visible_fraction": self.visible_fraction, "clipped": self.clipped}
        for key in ("size", "facing_deg", "height", "elevation_deg"):
            value = getattr(self, key)
            if value is not None:
                out[key] = list(value) if isinstance(value, tuple) else value
        if self.visible_px is not None:
            out["bbox_px"] = None if self.bbox_px is None else list(self.bbox_px)
            out["visible_px"] = self.visible_px
        return out

    @classmethod
    def from_json(cls, d: dict) -> ObjectTruth:
        """Inverse of :meth:`to_json`."""
        return cls(position=_pts(d["position"]), virtual=_pts(d["virtual"]),
                   alpha_deg=d["alpha_deg"], d_total=d["d_total"], d1=d["d1"], d2=d["d2"],
                   reflection_point=_pts(d["reflection_point"]),
                   elevation_deg=d.get("elevation_deg"),
                   mirror_offset=d["mirror_offset"], image_px=ImagePx(**d["image_px"]),
                   visible_fraction=d["visible_fraction"], clipped=d["clipped"],
                   size=_pt(d["size"]) if "size" in d else None,
                   facing_deg=d.get("facing_deg"), height=d.get("height"),
                   bbox_px=tuple(d["bbox_px"]) if d.get("bbox_px") else None,
                   visible_px=d.get("visible_px"))


@dataclass(frozen=True)
class RenderInfo:
    """How a frame was rendered."""

    variant: str
    spp: int
    seed: int
    sampler: str = "independent"
    background_spp: int | None = None  # outside the mirror's image (None: spp)
    beacon_spp: int | None = None  # in the beacons' images (None: spp)
    # each beacon box's, in the beacons' order (one whose image is off the film has none),
    # where a short image took more (RenderSettings.beacon_box_spp)
    beacon_box_spp: tuple[int, ...] | None = None
    seconds_render: float | None = None
    seconds_total: float | None = None
    mitsuba: str | None = None
    fingerprint: str | None = None
    # the SHA-256 of each file written with the truth (frame, capture record, ids), by
    # name: a cached frame is reused only while its bytes match
    files: dict[str, str] | None = None

    def to_json(self) -> dict:
        """The truth's ``render`` block."""
        return {"variant": self.variant, "spp": self.spp, "seed": self.seed,
                "sampler": self.sampler, "background_spp": self.background_spp,
                "beacon_spp": self.beacon_spp,
                **({"beacon_box_spp": list(self.beacon_box_spp)}
                   if self.beacon_box_spp is not None else {}),
                "seconds_render": self.seconds_render, "seconds_total": self.seconds_total,
                "mitsuba": self.mitsuba, "fingerprint": self.fingerprint,
                **({"files": dict(self.files)} if self.files is not None else {})}

    @classmethod
    def from_json(cls, d: dict) -> RenderInfo:
        """Inverse of :meth:`to_json`."""
        fields = ("variant", "spp", "seed", "background_spp", "beacon_spp", "seconds_render",
                  "seconds_total", "mitsuba", "fingerprint", "files")
        box = d.get("beacon_box_spp")
        return cls(**{k: d.get(k) for k in fields}, sampler=d.get("sampler", "independent"),
                   beacon_box_spp=None if box is None else tuple(box))


@dataclass(frozen=True)
class MirrorPixels:
    """Where the mirror's glass is seen in the frame (from the id pass)."""

    bbox_px: tuple[int, int, int, int] | None
    visible_px: int


@dataclass(frozen=True)
class GroundTruth:
    """The exact ground truth of a scene (``render``'s ``<name>.json``)."""

    scene: str
    camera: Camera
    mirror: Mirror
    target: ObjectTruth
    beacons: tuple[ObjectTruth, ...]
    occluders: tuple[Occluder, ...]
    direct_view_fraction: float
    mirror_pixels: MirrorPixels | None = None
    id_labels: dict[str, int] | None = None
    render: RenderInfo | None = None
    # the bench's imperfections by key path (None: an ideal bench), so that a frame's
    # truth says what it was rendered with
    bench: dict[str, Any] | None = None
    # the frame's masks, keypoints and virtual camera (a rendered frame's; None: none)
    annotations: Annotations | None = None

    @property
    def mirror_yaw_deg(self) -> float:
        """The mirror's yaw in [0, 180), rounded as its JSON is (so a truth read back from
        its file scores exactly as the one computed)."""
        return round(float(wrap_yaw(self.mirror.yaw)), 9)

    def to_json(self) -> dict:
        """The ground-truth document of docs/files.md."""
        cam, mir = self.camera, self.mirror
        mirror = {"center": point_list(mir.center, mir.z),
                  "yaw_deg": self.mirror_yaw_deg, "size": list(mir.size),
                  **({"lean_deg": mir.lean} if mir.lean else {})}
        if self.mirror_pixels is not None:
            mirror["bbox_px"] = (None if self.mirror_pixels.bbox_px is None
                                 else list(self.mirror_pixels.bbox_px))
            mirror["visible_px"] = self.mirror_pixels.visible_px
        out = {
            "scene": self.scene,
            "camera": {"position": list(cam.position), "height": cam.height,
                       "pan_deg": round(cam.pan_deg, 9), "hfov_deg": cam.hfov,
                       "resolution": list(cam.resolution), "fx": round(cam.fx, 9),
                       "fy": round(cam.fx, 9), "cx": cam.cx, "cy": cam.cy},
            "mirror": mirror,
            "target": self.target.to_json(),
            "beacons": [b.to_json() for b in self.beacons],
            "occluders": [{"start": list(o.start), "end": list(o.end), "height": o.height}
                          for o in self.occluders],
            "direct_view_fraction": self.direct_view_fraction,
        }
        if self.id_labels is not None:
            out["id_labels"] = dict(self.id_labels)
        if self.render is not None:
            out["render"] = self.render.to_json()
        if self.bench:
            out["bench"] = dict(self.bench)
        if self.annotations is not None:
            out["annotations"] = self.annotations.to_json()
        return out

    @classmethod
    def from_json(cls, d: dict) -> GroundTruth:
        """Inverse of :meth:`to_json` (the camera's pan is its resolved bearing)."""
        c, m = d["camera"], d["mirror"]
        camera = Camera(position=_pt(c["position"]), height=c["height"],
                        resolution=tuple(c["resolution"]), hfov=c["hfov_deg"],
                        pan=c["pan_deg"], pan_deg=c["pan_deg"])
        pixels = None
        if "visible_px" in m:
            pixels = MirrorPixels(tuple(m["bbox_px"]) if m["bbox_px"] else None,
                                  m["visible_px"])
        return cls(scene=d["scene"], camera=camera,
                   mirror=Mirror(_pt(m["center"]), m["yaw_deg"], _pt(m["size"]),
                                 lean=m.get("lean_deg", 0.0),
                                 z=m["center"][2] if len(m["center"]) > 2 else 0.0),
                   target=ObjectTruth.from_json(d["target"]),
                   beacons=tuple(ObjectTruth.from_json(b) for b in d["beacons"]),
                   occluders=tuple(Occluder(_pt(o["start"]), _pt(o["end"]), o["height"])
                                   for o in d["occluders"]),
                   direct_view_fraction=d["direct_view_fraction"], mirror_pixels=pixels,
                   id_labels=d.get("id_labels"),
                   render=RenderInfo.from_json(d["render"]) if "render" in d else None,
                   bench=d.get("bench"),
                   annotations=Annotations.from_json(d["annotations"])
                   if "annotations" in d else None)

    def in_plan(self) -> GroundTruth:
        """The truth as the planar solve sees it: a 3-D scene's points in plan, its
        d_total's horizontal part (d_total·cos ε), no elevation (a planar truth as it
        is)."""
        if self.target.elevation_deg is None:
            return self

        def flat(o: ObjectTruth) -> ObjectTruth:
            c = math.cos(math.radians(o.elevation_deg))
            return replace(o, position=o.position[:2], virtual=o.virtual[:2],
                           reflection_point=o.reflection_point[:2], d_total=_r(o.d_total * c),
                           d1=_r(o.d1 * c), d2=_r(o.d2 * c), elevation_deg=None)

        return replace(self, target=flat(self.target),
                       beacons=tuple(flat(b) for b in self.beacons))

    def exact_measurements3(self) -> Measurements3:
        """A 3-D truth's noise-free measurements in 3-D: each base's exact image (α, ε,
        d_total), the beacons' bases and the lens's position (``check --measurements``
        of a 3-D scene, which ``solve`` solves in 3-D)."""
        def seen(o: ObjectTruth) -> tuple[float, float, float]:
            return (o.alpha_deg, o.elevation_deg, o.d_total)

        return Measurements3(observer=tuple(float(c) for c in self.camera.center3),
                             beacons=tuple((b.position, seen(b)) for b in self.beacons),
                             target=seen(self.target), pan_deg=self.camera.pan_deg)

    def exact_measurements(self) -> Measurements:
        """The noise-free measurements of this truth (what a perfect detector reports);
        a 3-D truth's in plan (:meth:`in_plan`: what a planar solve can be given)."""
        if self.target.elevation_deg is not None:
            return self.in_plan().exact_measurements()
        return Measurements(
            observer=self.camera.position,
            targets=[(self.target.alpha_deg, self.target.d_total)],
            beacons=[BeaconMeasurement(b.position, b.alpha_deg, b.d_total)
                     for b in self.beacons])


def ground_truth(scene: Scene) -> GroundTruth:
    """The exact ground truth of a scene; the renderer adds what its id pass sees.

    Raises
    ------
    BadParameter
        ``scene`` is not a :class:`~mirrorsim.scene.model.Scene`.
    """
    check_is_scene(scene)
    cam, mir = scene.camera, scene.mirror

    def entry(obj, **extra) -> ObjectTruth:
        img = optics.object_image(scene, obj)
        position = tuple(obj.position)
        if scene.is_3d:  # the base's image in the mirror's plane, lean and heights counted
            position = tuple(float(c) for c in obj.base3)
            extra["elevation_deg"] = _r(img.elevation_deg)
        ext = optics.image_extent(scene, obj)
        vis = visibility.visibility(scene, obj)
        return ObjectTruth(
            position=position, virtual=_rs(img.virtual), alpha_deg=_r(img.alpha_deg),
            d_total=_r(img.d_total), d1=_r(img.d1), d2=_r(img.d2),
            reflection_point=_rs(img.reflection_point),
            mirror_offset=_r(optics.along_mirror(mir, img.reflection_point[:2])),
            image_px=ImagePx(_r(ext.u_axis), _r(ext.v_top), _r(ext.v_bottom),
                             _r(ext.height)),
            visible_fraction=_r(vis.fraction), clipped=vis.clipped, **extra)

    return GroundTruth(
        scene=scene.name, camera=cam, mirror=mir,
        target=entry(scene.target, size=tuple(scene.target.size),
                     facing_deg=_r(scene.target.facing_deg)),
        beacons=tuple(entry(b, height=b.height) for b in scene.beacons),
        occluders=scene.occluders,
        direct_view_fraction=_r(visibility.direct_view_fraction(scene, scene.target)),
        bench=as_keys(scene) or None)


def _r(x: float) -> float:
    """Round for JSON: 1e-9 cm / deg is far below anything measurable."""
    return round(float(x), 9)


def _rs(v) -> tuple[float, ...]:
    """A point's coordinates rounded for JSON (two, or three in a 3-D scene)."""
    return tuple(_r(c) for c in v)


def load_truth(path: Path) -> GroundTruth:
    """A frame's truth file, its checksum verified (:func:`~mirrorsim.formats.cache.unseal`).

    Raises
    ------
    ValueError
        For a file that is not a sealed truth document (OSError: unreadable).
    """
    return GroundTruth.from_json(unseal(json.loads(read_regular_bytes(path)), path.name))
