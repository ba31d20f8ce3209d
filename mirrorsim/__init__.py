"""mirrorsim: a physically rendered simulator of a mirror space for NLOS localization.

The Python API (each name is imported on first use, so that ``import mirrorsim`` stays
cheap)::

    import mirrorsim as ms
    scene = ms.load_scene("scenes/default.yaml")
    report = ms.evaluate(scene, "renders/default")      # render, detect, solve, score
    print(report.errors.target_cm, report.solution.ellipse95())

========================  ====================================================
``load_scene(path)``      a scene file → :class:`mirrorsim.scene.model.Scene`
``edit_scene(scene, changes)``  a scene with some of its file's keys changed, checked
``check(scene)``          the exact ground truth (:class:`GroundTruth`)
``render(scene, out)``    render and write a frame's files (:class:`FrameFiles`)
``load_capture(path)``    a capture record (what the experimenter knows)
``detect(frame, capture)``  measure a frame (:class:`MeasuredFrame`)
``solve(...)``            the mirror and the target from measurements
``BeaconMeasurement(...)``  one beacon's known position and its image's α, d_total
``load_measurements(path)``  a measurements file (what ``detect`` writes)
``SelfCalibration(...)``  what ``solve``, ``evaluate``, ``budget``, ``plan`` and
                          ``generate_dataset`` self-calibrate (``calibration=``)
``evaluate(scene, out)``  render → detect → solve → score (:class:`Report`; a 3-D
                          scene's: :class:`Report3`)
``budget(scene, out)``    the error budget of a bench (:class:`Budget`)
``track(scene, out)``     the moving beacon on rendered frames (:class:`TrackReport`)
``plan(scene)``           beacon placement (:class:`Plan`)
``generate_dataset(n, seed, out)``  a dataset of random scenes (:class:`DatasetRun`)
``load_dataset(folder)``  a dataset's table, verified, as a pandas DataFrame
``FrameDataset(folder)``  a dataset's frames with masks, keypoints, truth and
                          measurements, as a sequence (a PyTorch ``DataLoader`` takes it)
``export_dataset(folder)``  a dataset's COCO file, Hugging Face card and Croissant file
``fit_error_model(folder)``  the error model of a dataset
``load_error_model(path, kind)``  an error model file (``None``: the shipped one of
                          ``kind``, ``"ideal"`` or ``"bench"``)
``model_for(scene)``      the shipped model a scene's bench calls for
========================  ====================================================
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"

# name → (module, attribute): the entry points, each declared once in its wing
_API = {
    "load_scene": ("mirrorsim.pipelines.scenes", "load_scene"),
    "edit_scene": ("mirrorsim.pipelines.scenes", "edit_scene"),
    "check": ("mirrorsim.truth.groundtruth", "ground_truth"),
    "render": ("mirrorsim.pipelines.frame", "render_to_files"),
    "load_capture": ("mirrorsim.formats.capture", "load_capture"),
    "detect": ("mirrorsim.pipelines.frame", "measure_frame"),
    "solve": ("solver.lsq", "solve_measurements"),
    "BeaconMeasurement": ("solver.measurements", "BeaconMeasurement"),
    "load_measurements": ("mirrorsim.formats.measurements", "load_measurements"),
    "SelfCalibration": ("solver.selfcal", "SelfCalibration"),
    "evaluate": ("mirrorsim.pipelines.evaluate", "evaluate_scene"),
    "budget": ("mirrorsim.pipelines.budget", "run_budget"),
    "track": ("mirrorsim.pipelines.track", "run_track"),
    "plan": ("mirrorsim.pipelines.planning", "plan_scene"),
    "generate_dataset": ("mirrorsim.pipelines.dataset", "run_dataset"),
    "load_dataset": ("mirrorsim.formats.dataset_folder", "load_dataset"),
    "FrameDataset": ("mirrorsim.pipelines.frame_dataset", "FrameDataset"),
    "export_dataset": ("mirrorsim.pipelines.dataset_exports", "write_exports"),
    "fit_error_model": ("mirrorsim.pipelines.errormodel", "fit_dataset"),
    "load_error_model": ("mirrorsim.formats.error_model_file", "load_error_model_or_default"),
    "model_for": ("mirrorsim.pipelines.solving", "model_for"),
}
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        module, attr = _API[name]
        value = getattr(importlib.import_module(module), attr)
        if not isinstance(value, type):  # a class checks its own fields
            from mirrorsim.arguments import checked

            # every argument held to its type hint before any work (a wrong one named)
            value = checked(value)
        globals()[name] = value  # once imported, an ordinary attribute
        return value
    raise AttributeError(f"module 'mirrorsim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
