"""The hostile harness (tests/hostile.py) run whole, its verdicts counted per class.

    python benchmarks/hostile.py [--cheap] [--show]

Prints a Markdown table: per class, the cases run and the clean ones; ``--show`` lists
each case that is not clean with what went wrong.  The same cases run in the test
suite (tests/test_hostile.py); this script is for the counts a closing note gives.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import clone  # noqa: F401  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

from tests.hostile import CASES, CLASSES, run  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cheap", action="store_true", help="only the cases that render nothing")
    ap.add_argument("--show", action="store_true", help="list the cases that are not clean")
    args = ap.parse_args()
    cases = [c for c in CASES if c.cheap or not args.cheap]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="mirrorsim-hostile-") as tmp:
        results = run(cases, Path(tmp))
    print("| class | cases | clean |\n|---|---|---|")
    for cls in CLASSES:
        got = results[cls]
        print(f"| {cls} | {len(got)} | {sum(not v for _, v in got)} |")
    total = [v for cls in CLASSES for _, v in results[cls]]
    print(f"| all | {len(total)} | {sum(not v for v in total)} |")
    print(f"\n{time.perf_counter() - t0:.0f} s; {stamp()}")
    if args.show:
        print()
        for cls in CLASSES:
            for name, verdict in results[cls]:
                if verdict:
                    print(f"- {cls}: {name}: {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
