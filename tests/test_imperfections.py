"""The registry of bench imperfections: each declared once, and every reader obeys it."""

import copy
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import yaml

from mirrorsim.errors import SceneError
from mirrorsim.pipelines import error_features, random_scenes
from mirrorsim.pipelines.scenes import scene_from_dict
from mirrorsim.scene import imperfections
from mirrorsim.scene.imperfections import REGISTRY
from mirrorsim.scene.model import Bench

ROOT = Path(__file__).resolve().parents[1]
BASE = yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text())


def _with(key: str, value) -> dict:
    d = copy.deepcopy(BASE)
    block, leaf = key.split(".")
    d.setdefault(block, {})[leaf] = value
    return d


def test_every_bench_field_is_declared_once():
    declared = [imp.field for imp in REGISTRY if imp.block != "beacons"]
    assert sorted(declared) == sorted(f.name for f in fields(Bench))
    assert len({imp.key for imp in REGISTRY}) == len(REGISTRY)
    columns = [c.name for imp in REGISTRY for c in imp.columns]
    assert len(set(columns)) == len(columns)
    assert all(c.startswith("bench_") for c in columns)


# bounds fixed here, apart from the registry: beyond them a value is a typo, not a bench
BOUNDS = {"camera.pan_error": (10.0, "°"), "camera.pitch": (20.0, "°"),
          "camera.roll": (30.0, "°"), "mirror.tilt": (45.0, "°")}


@pytest.mark.parametrize("key", sorted(BOUNDS))
def test_angles_are_read_within_their_bounds(key):
    bound = BOUNDS[key][0]
    field = next(imp.field for imp in REGISTRY if imp.key == key)
    inside = scene_from_dict(_with(key, 0.05 * bound))
    assert getattr(inside.bench, field) == pytest.approx(0.05 * bound)
    with pytest.raises(SceneError) as err:
        scene_from_dict(_with(key, -bound))
    assert err.value.key == key and "must stay below" in err.value.message


def test_other_forms_are_read_and_bounded():
    s = scene_from_dict(_with("calibration.distance_error", 2.5))
    assert s.bench.calibration_distance_error == 2.5
    with pytest.raises(SceneError, match="calibration.distance_error"):
        scene_from_dict(_with("calibration.distance_error", -50))
    assert scene_from_dict(_with("camera.jpeg_quality", 80)).bench.jpeg_quality == 80
    with pytest.raises(SceneError, match="camera.jpeg_quality"):
        scene_from_dict(_with("camera.jpeg_quality", 101))
    with pytest.raises(SceneError, match="camera.distortion_known"):
        scene_from_dict(_with("camera.distortion_known", "no"))
    # the mirror of default.yaml is 18.2 × 13.25 cm: its diagonal is 22.51 cm
    with pytest.raises(SceneError, match=r"diagonal \(22.5 cm\)"):
        scene_from_dict(_with("mirror.curvature_radius", -22.4))


def test_a_row_holds_each_imperfection_as_declared():
    d = _with("mirror.curvature_radius", 250.0)
    d["camera"].update(jpeg_quality=70, noise={"full_well": 4000, "read_noise": 3})
    d["beacon"]["known_position"] = [d["beacon"]["position"][0] + 0.5,
                                     d["beacon"]["position"][1] - 0.25]
    row = imperfections.row_values(scene_from_dict(d))
    assert tuple(row) == imperfections.ROW_COLUMNS
    assert row["bench_curvature_per_cm"] == pytest.approx(1 / 250)
    assert row["bench_jpeg_quality"] == 70
    assert (row["bench_full_well"], row["bench_read_noise"]) == (4000, 3)
    assert row["bench_beacon_dx_cm"] == pytest.approx(0.5)
    assert row["bench_beacon_dy_cm"] == pytest.approx(-0.25)
    ideal = imperfections.row_values(scene_from_dict(BASE))
    assert ideal["bench_full_well"] == 0 and ideal["bench_jpeg_quality"] == 0
    assert ideal["bench_curvature_per_cm"] == 0 and ideal["bench_distortion_known"] is True


def test_the_spec_and_the_error_model_know_every_imperfection():
    spec_paths = {f"{b}.{k}" for b, keys in random_scenes.BENCH_SPEC_KEYS.items() for k in keys}
    assert spec_paths == {imp.spec_path for imp in REGISTRY}
    assert set(error_features.BENCH_FEATURES) == {f.name for f in imperfections.FEATURES}


def test_features_against_their_first_order_forms():
    # two rows: a flat mirror and R = 200 cm; an uncorrected lens k1 = 0.1 at 20° off axis
    cols = {"target_incidence_deg": [30.0, 30.0], "target_d1": [40.0, 40.0],
            "target_d2": [60.0, 60.0], "target_d_true": [100.0, 100.0],
            "bench_curvature_per_cm": [0.0, 1 / 200], "bench_k1": [0.1, 0.1],
            "bench_distortion_known": [False, True], "target_off_axis_deg": [20.0, 20.0],
            "bench_full_well": [0.0, 10000.0], "bench_read_noise": [0.0, 5.0],
            "bench_jpeg_quality": [0, 90]}
    f = {name: error_features._feature(cols, "target", name)
         for name in error_features.BENCH_FEATURES
         if name not in ("pan_error_deg", "pitch_deg", "roll_deg", "tilt_deg",
                         "calibration_error_cm")}
    power = 2 * np.cos(np.radians(30)) * 40 * 60 / (200 * 100)
    np.testing.assert_allclose(f["mirror_power"], [0.0, power])
    np.testing.assert_allclose(f["k1_tan3"], [0.1 * np.tan(np.radians(20)) ** 3, 0.0])
    np.testing.assert_allclose(f["shot_noise"], [0.0, 0.01])
    np.testing.assert_allclose(f["read_noise_rel"], [0.0, 5e-4])
    np.testing.assert_allclose(f["jpeg_loss"], [0.0, 0.1])


def test_a_row_off_its_declared_columns_is_refused_where_it_is_made():
    from mirrorsim.formats import dataset_table as table

    fine = dict.fromkeys(table.NAMES, 0.0) | {"error": ""}
    assert table.checked_row(fine) is fine
    with pytest.raises(ValueError, match="unknown.*target_alpha_eror"):
        table.checked_row(fine | {"target_alpha_eror": 1.0})
    with pytest.raises(ValueError, match="missing.*beacon_d_meas"):
        table.checked_row({k: v for k, v in fine.items() if k != "beacon_d_meas"})
    failed = {"index": 3, "scene": "scene000003", "seed": 1, "schema": 1,
              "error": "DetectionError: nothing found", "traceback": "…",
              "seconds_total": 1.0}
    assert table.checked_row(failed) is failed


def test_null_is_absent_only_where_the_ideal_bench_has_none():
    # no lens, no noise, no JPEG, a flat mirror: null says "none"; a number must be one
    assert scene_from_dict(_with("camera.noise", None)).bench == Bench()
    assert scene_from_dict(_with("mirror.curvature_radius", None)).bench == Bench()
    for key in ("camera.pan_error", "mirror.tilt", "calibration.distance_error",
                "camera.distortion_known"):
        with pytest.raises(SceneError, match=key.replace(".", r"\.")):
            scene_from_dict(_with(key, None))


@pytest.mark.parametrize("name", ["default", "exp1", "exp2", "exp3"])
def test_each_column_s_ideal_value_is_what_an_ideal_bench_gives(name):
    """A row written before an imperfection existed takes its column's ``ideal`` value:
    the value the column reads off the same scene on an ideal bench."""
    from mirrorsim.pipelines.scenes import load_scene

    scene = imperfections.ideal(load_scene(Path(__file__).parents[1] / "scenes"
                                           / f"{name}.yaml"))
    for imp in imperfections.REGISTRY:
        for c in imp.columns:
            assert c.of(scene) == c.ideal, c.name


def test_a_new_imperfection_brings_its_row_layout_and_its_migration(monkeypatch):
    """Adding an imperfection is its registry entry: with ``since`` the next layout, the
    table's version moves to it and a row of the layout before takes the new column's
    ideal value, with no other file touched."""
    from dataclasses import replace

    from mirrorsim.formats import dataset_table as table

    assert (table.SCHEMA, table.ADDED_IN) == table.layouts()  # today's, from the registry
    shake = replace(imperfections.REGISTRY[1], field="shake", key="camera.shake",
                    since=table.SCHEMA + 1, features=(),
                    columns=(imperfections.Column("bench_shake_deg", "deg", "camera shake",
                                                  lambda _s: 0.0),))
    schema, added = table.layouts((*imperfections.REGISTRY, shake))
    assert schema == table.SCHEMA + 1
    assert added[schema] == {"bench_shake_deg": 0.0}
    assert {k: v for k, v in added.items() if k < schema} == table.ADDED_IN
    monkeypatch.setattr(table, "ADDED_IN", added)
    older = table.older_values(table.SCHEMA)  # a row of today's layout, read tomorrow
    assert older == {"bench_shake_deg": 0.0}
    assert table.older_values(2)["bench_shake_deg"] == 0.0 and "beacons" in \
        table.older_values(2)
