"""Importing this puts the clone's root first on ``sys.path``: a benchmark measures the
code beside it (``mirrorsim``, ``solver``, ``tests``), not another installed copy.  Every
script runs with ``benchmarks/`` as its own folder on the path, so ``from clone import
ROOT`` is the one line each needs."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path[:1]:
    sys.path.insert(0, str(ROOT))
