"""The docs and the README hold to what made them: generated references equal the
code's declarations, every included result comes from a registered command and carries
its stamp, the README's quick-start table is the demo's, nothing sends a reader outside
the repository, and the README's Python quick start runs."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"docs_{name}", DOCS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[f"docs_{name}"] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _includes() -> dict[str, list[str]]:
    """Each page's ``--8<--`` includes."""
    return {p.name: re.findall(r'^--8<-- "([^"]+)"', p.read_text(encoding="utf-8"), re.M)
            for p in DOCS.glob("*.md")}


def test_the_generated_references_are_the_codes_declarations():
    gen = _module("gen_reference")
    for name, text in gen.pages().items():
        assert (DOCS / "generated" / name).read_text(encoding="utf-8") == text, (
            f"docs/generated/{name} is out of date: run python docs/gen_reference.py")


def test_every_included_result_comes_from_a_registered_command_with_its_stamp():
    reg = _module("regenerate")
    included = [f for fs in _includes().values() for f in fs]
    assert "generated/bench_keys.md" in included and "results/demo.md" in included
    for f in included:
        path = DOCS / f
        assert path.exists(), f"an include names {f}, which does not exist"
        if f.startswith("results/"):
            name = Path(f).stem
            assert name in reg.BY_NAME, f"{f} has no command in docs/regenerate.py"
            text = path.read_text(encoding="utf-8")
            r = reg.BY_NAME[name]
            # its header, then the commands that made it and the stamp
            assert text.startswith(reg.HEADER.format(name=name)), f
            stamp_line = text.split("\n")[2]
            for c in r.commands:
                assert f"`{c}`" in stamp_line, f"{f} was made by another command than {c}"
            # a commit, not a dirty tree's "-dirty": the result is of committed code
            assert re.search(r"commit [0-9a-f]{7,}, \d{4}-\d\d-\d\d, ", stamp_line), f
            # no terminal colours, log lines or machine paths in what the pages show
            assert "\x1b" not in text and not re.search(r"(^|\s)/(tmp|home|root|work)/", text), f


def test_every_registered_result_is_shown_somewhere():
    reg = _module("regenerate")
    included = {Path(f).stem for fs in _includes().values() for f in fs
                if f.startswith("results/")}
    assert set(reg.BY_NAME) <= included, set(reg.BY_NAME) - included


def test_the_readme_quick_start_table_is_the_demos():
    reg = _module("regenerate")
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = readme.split(reg.README_BEGIN)[1].split(reg.README_END)[0]
    demo = (DOCS / "results" / "demo.md").read_text(encoding="utf-8")
    assert block.strip() == reg.demo_block(demo).strip()
    assert "(reused)" not in block  # what a fresh clone prints


def test_the_readme_is_a_front_door():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 300
    for word in ("this round", "this stop", "/work/"):
        assert word not in readme, word


def test_nothing_in_the_repository_sends_a_reader_outside_it():
    """No tracked text file names a path above the repository's folder, or a Markdown
    file that the repository does not hold (the bad-input corpus aside: its paths are
    the point)."""
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split()
    held = {Path(f).name for f in files if f.endswith(".md")}
    offenders = []
    for f in files:
        if f.startswith("tests/bad_scenes/") or not f.endswith(
                (".py", ".md", ".yaml", ".yml", ".toml", ".txt", ".json")):
            continue
        text = (ROOT / f).read_text(encoding="utf-8", errors="replace")
        above = re.findall(r"(?<![\w.])\.\./\w", text)
        absent = {m for m in re.findall(r"([\w-]+\.md)\b", text) if m not in held}
        if above or absent:
            offenders.append((f, above, sorted(absent)))
    assert not offenders, offenders


@pytest.mark.slow
def test_the_readme_python_quick_start_runs(tmp_path):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    code = readme.split("<!-- python quick start")[1].split("```python\n")[1].split("```")[0]
    code = code.replace('"scenes/default.yaml"', repr(str(ROOT / "scenes" / "default.yaml")))
    code = code.replace('"renders/quickstart"', repr(str(tmp_path / "quickstart")))
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=tmp_path, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    assert re.search(r"target error \d+\.\d{3} cm, 95 % ellipse semi-major \d+\.\d{3} cm",
                     p.stdout)


@pytest.mark.slow
def test_make_demo_prints_the_readme_table(tmp_path):
    """A fresh render of the default scene prints the README's table to the printed
    digits (the output folder's lines aside)."""
    reg = _module("regenerate")
    demo = (DOCS / "results" / "demo.md").read_text(encoding="utf-8")
    want = reg.demo_block(demo).split("```text\n")[1].split("```")[0]
    p = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "evaluate",
                        str(ROOT / "scenes" / "default.yaml"), "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    keep = lambda text: [ln for ln in text.splitlines()  # noqa: E731
                         if not ln.startswith(("report:", "top view:", "annotated:"))]
    assert keep(p.stdout) == keep(want)


def test_every_key_of_the_template_scene_is_in_the_scene_reference():
    """The reference table names every key the template (`mirrorsim new`) writes, and
    every bench key of the registry (its own generated table)."""
    import yaml

    from mirrorsim.formats.template import scene_template

    doc = re.sub(r'^--8<-- "([^"]+)"',
                 lambda m: (DOCS / m.group(1)).read_text(encoding="utf-8"),
                 (DOCS / "scenes.md").read_text(encoding="utf-8"), flags=re.M)
    data = yaml.safe_load(scene_template("x.yaml"))

    def paths(value, prefix=""):
        if isinstance(value, dict):
            for k, v in value.items():
                yield from paths(v, f"{prefix}.{k}" if prefix else k)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            for item in value:
                yield from paths(item, prefix)
        else:
            yield prefix

    for key in set(paths(data)):
        leaf = key.split(".")[-1]
        assert f"`{key}`" in doc or f".{leaf}`" in doc or f"`{leaf}`" in doc, key
