"""A dataset's frame table, declared once: ``DIR/metadata.jsonl`` holds one line per
frame with these fields, the card's Hugging Face front matter declares them as its
features, and ``DIR/croissant.json`` as its record set's fields (both made here, from
:data:`FIELDS`).  :mod:`mirrorsim.pipelines.dataset_exports` fills the lines.

A field is a scalar (``string``, ``int64``, ``float64``), a list of one (``list
float64``), the frame (``image``: its ``file_name``, as Hugging Face's image folders
take it), or the list of the frame's instances (``objects``, whose subfields are
:data:`OBJECT_FIELDS`).
"""

from __future__ import annotations

from dataclasses import dataclass

import yaml

from mirrorsim.formats.files import FRAME_SUFFIXES


@dataclass(frozen=True)
class Field:
    """One field of the frame table: its name, its type and what it holds."""

    name: str
    dtype: str  # string, int64, float64, image, "list <scalar>", or objects
    doc: str


OBJECT_FIELDS = (
    Field("object", "string", "`target`, `beacons[i]` or `mirror`"),
    Field("view", "string", "`direct`, or `mirror`: its image in the glass"),
    Field("category", "string", "the COCO category: `target_in_mirror`, `beacon_in_mirror`, "
                                "`target_direct`, `beacon_direct`, `mirror`"),
    Field("bbox", "list int64", "x, y, width, height of its mask (px)"),
    Field("area", "int64", "its mask's pixels"),
    Field("mask_counts", "string", "its mask as COCO's compressed RLE counts (size: the "
                                   "frame's height, width)"),
    Field("keypoints", "list float64", "u, v, visibility per keypoint, as COCO lists them "
                                       "(0 off the frame, 1 hidden, 2 seen)"),
)
FIELDS = (
    Field("image", "image", "the frame (`file_name`: its path in the folder)"),
    Field("scene", "string", "the scene's name (`scenes/<scene>.yaml`)"),
    Field("index", "int64", "the scene's number"),
    Field("frame", "string", "the frame's name (a scene of several beacons has one a beacon)"),
    Field("truth_file", "string", "its ground truth, with every annotation"),
    Field("measurements_file", "string", "what the solver was given (empty: none)"),
    Field("width", "int64", "frame width (px)"), Field("height", "int64", "frame height (px)"),
    Field("error", "string", "why the scene failed to evaluate (empty if fine)"),
    Field("target_alpha_true", "float64", "exact α of the target's image (deg; the table's "
                                          "`target_alpha_true`)"),
    Field("target_d_true", "float64", "exact d_total of the target's image (cm; the table's "
                                      "`target_d_true`)"),
    Field("target_alpha_meas", "float64", "measured α (deg; null: failed)"),
    Field("target_d_meas", "float64", "measured d_total (cm; null: failed)"),
    Field("err_target_cm", "float64", "the located target's error (cm; null: failed)"),
    Field("camera_intrinsics", "list float64", "the 3×3 camera matrix, row by row (px)"),
    Field("virtual_camera", "list float64", "the mirror's virtual camera: the 4×4 "
                                            "world-to-camera matrix, row by row (cm)"),
    Field("lens_distortion", "list float64", "the lens's radial distortion k1, k2 (the "
                                             "keypoints include it; 0, 0: none)"),
    Field("objects", "objects", "each object seen each way: mask, box, keypoints"),
)
_CROISSANT_TYPES = {"string": "sc:Text", "int64": "sc:Integer", "float64": "sc:Float"}


def _hf_feature(f: Field) -> dict:
    """A field as the Hub's ``dataset_info.features`` YAML lists it."""
    if f.dtype == "objects":
        return {"name": f.name, "list": [_hf_feature(s) for s in OBJECT_FIELDS]}
    if f.dtype.startswith("list "):
        return {"name": f.name, "list": f.dtype.split()[1]}
    return {"name": f.name, "dtype": f.dtype}


def front_matter(frames: int, image_globs: tuple[str, ...]) -> str:
    """The card's YAML front matter: licence, tasks, size, the frame table as the default
    configuration's train split (``metadata.jsonl`` and the frames it names), and its
    features."""
    size = ("n<1K" if frames < 1_000 else "1K<n<10K" if frames < 10_000
            else "10K<n<100K" if frames < 100_000 else "100K<n<1M" if frames < 1_000_000
            else "n>1M")
    doc = {"license": "cc-by-4.0",
           "task_categories": ["object-detection", "image-segmentation", "keypoint-detection"],
           "tags": ["synthetic", "mirror", "non-line-of-sight", "mitsuba", "mirrorsim"],
           "size_categories": [size], "pretty_name": "mirrorsim frames",
           "configs": [{"config_name": "default", "data_files": [
               {"split": "train", "path": ["metadata.jsonl", *image_globs]}]}],
           "dataset_info": {"features": [_hf_feature(f) for f in FIELDS]}}
    return "---\n" + yaml.safe_dump(doc, sort_keys=False, allow_unicode=True) + "---\n"


def croissant(name: str, *, description: str, image_globs: tuple[str, ...],
              metadata_sha256: str, date: str) -> dict:
    """``croissant.json``: the frame table (``metadata.jsonl``) as the record set
    ``frames`` (its scalar and list fields: the instances' list is the frame table's and
    the COCO file's), and the frames' files as ``images`` (each one's path in the
    folder and content: join the two on ``file_name``; a dataset of PNG and JPEG frames
    has a file set and a record set of each, ``images`` and ``images1``)."""
    def field(rs: str, f: Field) -> dict:
        out = {"@type": "cr:Field", "@id": f"{rs}/{f.name}", "name": f.name,
               "description": f.doc, "dataType": _CROISSANT_TYPES[f.dtype.split()[-1]],
               "source": {"fileObject": {"@id": "metadata"},
                          "extract": {"column": f.name}}}
        if f.dtype.startswith("list "):
            out["repeated"] = True
        return out

    scalars = [f for f in FIELDS if f.dtype not in ("image", "objects")]
    frames = [field("frames", Field("file_name", "string", "the frame's path in the folder")),
              *(field("frames", f) for f in scalars)]

    def images(k: int) -> dict:
        """The record set of file set k's frames: each one's path and content."""
        rs, files = ("images" if k == 0 else f"images{k}"), {"@id": f"frame-files{k}"}
        return {"@type": "cr:RecordSet", "@id": rs, "name": rs,
                "description": "the frames' files (join with frames on file_name)",
                "field": [{"@type": "cr:Field", "@id": f"{rs}/file_name", "name": "file_name",
                           "description": "the frame's path in the folder",
                           "dataType": "sc:Text",
                           "source": {"fileSet": files, "extract": {"fileProperty": "filepath"},
                                      # its path in the folder, as the frame table names it
                                      "transform": {"regex": "^.*/(frames/[^/]+/[^/]+)$"}}},
                          {"@type": "cr:Field", "@id": f"{rs}/image", "name": "image",
                           "description": "the frame", "dataType": "sc:ImageObject",
                           "source": {"fileSet": files,
                                      "extract": {"fileProperty": "content"}}}]}

    return {
        "@context": _CONTEXT, "@type": "sc:Dataset", "name": name,
        "citeAs": "mirrorsim: a physically rendered simulator of a mirror space for NLOS "
                  "localization",
        "description": description, "conformsTo": "http://mlcommons.org/croissant/1.0",
        "license": "https://creativecommons.org/licenses/by/4.0/", "url": "https://example.org/"
        + name, "version": "1.0.0", "datePublished": date,
        "distribution": [
            {"@type": "cr:FileObject", "@id": "metadata", "name": "metadata",
             "contentUrl": "metadata.jsonl", "encodingFormat": "application/jsonlines",
             "sha256": metadata_sha256},
            *({"@type": "cr:FileSet", "@id": f"frame-files{k}", "name": f"frame-files{k}",
               "encodingFormat": "image/jpeg" if g.endswith(FRAME_SUFFIXES[1]) else "image/png",
               "includes": [g]} for k, g in enumerate(image_globs))],
        "recordSet": [{"@type": "cr:RecordSet", "@id": "frames", "name": "frames",
                       "description": "one record per frame", "field": frames},
                      *(images(k) for k in range(len(image_globs)))]}


# Croissant 1.0's JSON-LD context (its specification's, section "Dataset-level
# information")
_CONTEXT = {
    "@language": "en", "@vocab": "https://schema.org/", "sc": "https://schema.org/",
    "cr": "http://mlcommons.org/croissant/", "rai": "http://mlcommons.org/croissant/RAI/",
    "dct": "http://purl.org/dc/terms/", "samplingRate": "cr:samplingRate",
    "equivalentProperty": "cr:equivalentProperty", "citeAs": "cr:citeAs", "column": "cr:column",
    "conformsTo": "dct:conformsTo", "data": {"@id": "cr:data", "@type": "@json"},
    "dataType": {"@id": "cr:dataType", "@type": "@vocab"},
    "examples": {"@id": "cr:examples", "@type": "@json"}, "extract": "cr:extract",
    "field": "cr:field", "fileProperty": "cr:fileProperty", "fileObject": "cr:fileObject",
    "fileSet": "cr:fileSet", "format": "cr:format", "includes": "cr:includes",
    "isLiveDataset": "cr:isLiveDataset", "jsonPath": "cr:jsonPath", "key": "cr:key",
    "md5": "cr:md5", "parentField": "cr:parentField", "path": "cr:path",
    "recordSet": "cr:recordSet", "references": "cr:references", "regex": "cr:regex",
    "repeated": "cr:repeated", "replace": "cr:replace", "separator": "cr:separator",
    "source": "cr:source", "subField": "cr:subField", "transform": "cr:transform",
}
