"""The hostile harness (tests/hostile.py): every case clean.  The cheap ones (no render,
no dataset) run in the fast suite; the ones that make a small dataset or render a frame
are marked slow."""

from __future__ import annotations

import numpy as np
import pytest

from tests.hostile import CASES, CLASSES


def _param(c):
    marks = () if c.cheap else (pytest.mark.slow,)
    return pytest.param(c, id=f"{c.cls}: {c.name}", marks=marks)


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_hostile_case_is_clean(case, tmp_path):
    assert case.run(tmp_path) == ""


def test_the_harness_covers_every_class_with_at_least_60_cases():
    counts = {cls: sum(c.cls == cls for c in CASES) for cls in CLASSES}
    assert all(n >= 5 for n in counts.values()), counts
    assert len(CASES) >= 60


def _hostile_values(tp):
    """What a parameter of hint ``tp`` must refuse, derived from the hint alone:
    (label, value) pairs."""
    import math
    import typing

    from solver.arguments import ANY

    if tp is ANY:
        return []
    args = set(typing.get_args(tp)) if typing.get_origin(tp) in (
        typing.Union, type(int | None)) else {tp}
    out = [("a wrong type", object())]
    if type(None) not in args and None not in args:
        out.append(("None", None))
    if args & {int, float}:
        out += [("a bool for a number", True)]
    if float in args:
        out += [("NaN", math.nan), ("infinity", math.inf)]
    if bool in args:
        out += [("a string for a bool", "no")]
    return out


def _every_parameter():
    import dataclasses

    import mirrorsim as ms
    from mirrorsim.arguments import parameter_hints
    from solver.arguments import field_hints

    for name in ms.__all__[1:]:
        obj = getattr(ms, name)
        hints = (field_hints(obj) if isinstance(obj, type) and dataclasses.is_dataclass(obj)
                 else parameter_hints(_checked_function(obj)))
        for param, tp in hints.items():
            for label, value in _hostile_values(tp):
                yield pytest.param(name, param, value, id=f"{name}({param}=<{label}>)")


def _checked_function(obj):
    """What a public name checks its arguments with: a function's own, a class's
    ``__init__`` (a class that is not a dataclass checks there)."""
    return obj.__init__.__wrapped__ if isinstance(obj, type) else obj.__wrapped__


@pytest.mark.parametrize("name, param, value", list(_every_parameter()))
def test_every_public_name_refuses_each_hostile_value_by_its_hint(name, param, value):
    """Every name in ``mirrorsim.__all__``, every parameter with a type hint: each value
    its hint refuses raises BadParameter naming the parameter, before the function runs
    (the check binds the arguments only; the function is never called)."""
    import dataclasses

    import mirrorsim as ms
    from mirrorsim.arguments import check_arguments
    from mirrorsim.errors import BadParameter
    from solver.arguments import check_fields

    obj = getattr(ms, name)
    with pytest.raises(BadParameter, match=f"^{param}: "):
        if isinstance(obj, type) and dataclasses.is_dataclass(obj):  # its field check
            made = object.__new__(obj)
            for f in dataclasses.fields(obj):
                object.__setattr__(made, f.name, value if f.name == param
                                   else _FIELD_OK[f.name])
            check_fields(made)
        else:
            import inspect

            fn = _checked_function(obj)
            sig = inspect.signature(fn)
            this = (None,) if isinstance(obj, type) else ()  # an __init__'s self
            check_arguments(fn, this, {
                p: (value if p == param else _valid(sig.parameters[p]))
                for p in sig.parameters if p != "self" and (p == param or
                sig.parameters[p].default is inspect.Parameter.empty)})


_FIELD_OK = {"position": (1.0, 2.0), "alpha_deg": 1.0, "d_total": 50.0, "nuisances": (),
             "position_sigma": 0.0, "priors": {}}


def _valid(parameter):
    """A valid value for a required parameter other than the one under test: the check
    goes parameter by parameter in order, so one that conforms lets it reach ours."""
    import numpy as np

    import mirrorsim as ms
    from tests.hostile import DEFAULT

    valid = {"scene": ms.load_scene(DEFAULT), "path": DEFAULT, "changes": {},
             "out": "out", "image_path": "f.png", "capture": "c.capture.json",
             "observer": np.zeros(2), "beacons": [], "targets": [], "n": 1, "seed": 0,
             "folder": "ds", "dataset_dir": "ds"}
    return valid[parameter.name]


@pytest.mark.parametrize("name, param, value, plain", [
    ("track", "steps", np.int64(3), int), ("track", "odometry_sigma", np.float32(0.5), float),
    ("generate_dataset", "seed", np.uint16(7), int),
    ("plan", "eps_deg", np.float64(4.0), float), ("plan", "n_beacons", np.int32(2), int),
    ("detect", "distance_error", np.float16(1.0), float),
    ("evaluate", "board_pose", np.bool_(True), bool),
])
def test_numpy_scalars_are_taken_as_plain_numbers(name, param, value, plain):
    import inspect

    import mirrorsim as ms
    from mirrorsim.arguments import check_arguments

    fn = getattr(ms, name).__wrapped__
    sig = inspect.signature(fn)
    bound = check_arguments(fn, (), {
        p: (value if p == param else _valid(sig.parameters[p]))
        for p in sig.parameters
        if p == param or sig.parameters[p].default is inspect.Parameter.empty})
    assert type(bound.arguments[param]) is plain and bound.arguments[param] == value
