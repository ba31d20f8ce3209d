"""A Griffe extension for the API page (mkdocs.yml loads it): the docstrings' Sphinx
roles (``:class:`~mirrorsim.pipelines.score.Report```, ``:func:`solve```) become code
spans with the object's short name, as the page shows them; left alone they were shown
raw (``:class:`` then the path)."""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|data|mod|attr|obj|exc):`(~?)([^`]+)`")


def plain(text: str) -> str:
    """``text`` with each role made a code span (``~`` keeps the last dotted name)."""
    return ROLE.sub(lambda m: f"`{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}`", text)


class SphinxRoles(griffe.Extension):
    """Rewrite the roles of every docstring Griffe loads."""

    def on_instance(self, *, obj: griffe.Object, **_kwargs: Any) -> None:
        """One object's docstring."""
        if obj.docstring is not None:
            obj.docstring.value = plain(obj.docstring.value)
