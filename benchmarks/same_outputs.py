"""Whether a change left every command's output alone: ``evaluate``, ``check`` and
``plan --json`` of the four bundled scenes, at a commit of before and at this checkout,
compared up to timing fields and paths.

    python benchmarks/same_outputs.py --before COMMIT

The commit is checked out in a temporary git worktree and run from there (its own
``mirrorsim`` first on ``PYTHONPATH``); each scene renders anew in each.  Prints each
scene's count of differing fields and the first few, and exits 1 if any differs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from clone import ROOT
from stamp import stamp

SCENES = ("default", "exp1", "exp2", "exp3")
# what differs between two runs of the same code: timings, file names and digests
VOLATILE = ("seconds", "fingerprint", "png", "annotated", "files")


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()
                if not any(k.startswith(w) for w in VOLATILE)}
    if isinstance(x, list):
        return [_plain(v) for v in x]
    return x


def differences(a, b, path: str = "") -> list[str]:
    """Where two JSON documents differ, as ``key.path: old -> new``."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}.{k}: only in {'after' if k in b else 'before'}")
            else:
                out += differences(a[k], b[k], f"{path}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} -> {b!r}"[:160]]


COMMANDS = ("evaluate", "check", "plan")


def output(root: Path, command: str, scene: str, out: Path) -> dict:
    """``command``'s JSON for ``scene``, run from the checkout at ``root``."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    extra = {"evaluate": ["--out", str(out), "--quiet"], "plan": ["--out", f"{out}.png"],
             "check": []}[command]
    subprocess.run([sys.executable, "-m", "mirrorsim", command, f"scenes/{scene}.yaml",
                    *extra, "--json", f"{out}.json"],
                   cwd=root, env=env, check=True, capture_output=True)
    return _plain(json.loads(Path(f"{out}.json").read_text()))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="the commit to compare with")
    args = ap.parse_args()
    differ = 0
    with tempfile.TemporaryDirectory(prefix="mirrorsim-same-") as tmp:
        old = Path(tmp) / "before"
        subprocess.run(["git", "worktree", "add", "--detach", str(old), args.before],
                       cwd=ROOT, check=True, capture_output=True)
        try:
            for scene in SCENES:
                for command in COMMANDS:
                    name = f"{command}_{scene}"
                    d = differences(output(old, command, scene, Path(tmp) / f"b_{name}"),
                                    output(ROOT, command, scene, Path(tmp) / f"a_{name}"))
                    differ += bool(d)
                    print(f"{command} {scene}: {len(d)} field(s) differ"
                          + "".join(f"\n  {x}" for x in d[:5]))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT,
                           capture_output=True)
    runs = len(SCENES) * len(COMMANDS)
    print(f"{runs - differ} of {runs} outputs ({', '.join(COMMANDS)} of {len(SCENES)} scenes) "
          f"unchanged against {args.before}; {stamp()}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
