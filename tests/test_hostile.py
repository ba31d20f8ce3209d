"""The hostile harness (tests/hostile.py): every case clean.  The cheap ones (no render,
no dataset) run in the fast suite; the ones that make a small dataset or render a frame
are marked slow."""

from __future__ import annotations

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
