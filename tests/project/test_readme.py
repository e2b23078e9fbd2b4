"""The README is a front door: short, the two commands first, and its "Bring your own clip"
recipe runs as written (import a real walk, play it on a 1.20 m body on stairs, render a frame),
printing what the README says it prints."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import MOCAP_DIR, REPO, require_mocap
from support.gl import need_gl

README = (REPO / "README.md").read_text(encoding="utf-8")
MAIN_JOB = ("python3 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/ecs-anim run "
            "scenarios/fight_training.yaml --export out/fight_training --report "
            "out/fight_training.json --force")
TESTS = "python3 -m venv .venv && .venv/bin/pip install -q -e '.[test]' && .venv/bin/python -m pytest -q -n auto --dist loadfile"
#: A newcomer reads it in five minutes (issue 30): the reference lives in docs/.
MAX_LINES = 250


def section(heading: str) -> str:
    start = README.index(f"\n## {heading}\n")
    end = README.find("\n## ", start + 1)
    return README[start:] if end < 0 else README[start:end]


def test_the_readme_is_short_and_opens_with_its_two_commands():
    assert README.count("\n") <= MAX_LINES
    first_section = section("Run it")
    assert MAIN_JOB in first_section and TESTS in first_section
    assert README.index(MAIN_JOB) < README.index("\n## Bring your own clip")


def test_the_bring_your_own_clip_recipe_runs_as_written(tmp_path: Path):
    """Its commands in order, in a folder laid out like the repository's (``../shared`` beside
    it), the window left out: the import, the scenario it writes, the run and the screenshot."""
    require_mocap()
    recipe = section("Bring your own clip")
    yaml_text = re.search(r"```yaml\n(.*?)```", recipe, re.DOTALL)
    assert yaml_text is not None
    yaml_path = re.search(r"Write a scenario, `([^`]+)`", recipe)
    assert yaml_path is not None
    commands = [line.strip() for line in recipe.splitlines()
                if line.strip().startswith(".venv/bin/ecs-anim ")]
    assert len(commands) == 4, commands  # import, run, view (a window), view --screenshot
    root = tmp_path / "repo"
    root.mkdir()
    (tmp_path / "shared").symlink_to(MOCAP_DIR.parent)
    ecs_anim = str(Path(sys.executable).with_name("ecs-anim"))
    outputs = []
    for command in commands:
        if command.startswith(".venv/bin/ecs-anim run"):  # the scenario exists by then
            scenario = root / yaml_path.group(1)
            scenario.write_text(re.sub(r"^   ", "", yaml_text.group(1), flags=re.M),
                                encoding="utf-8")
        if " view " in command and "--screenshot" not in command:
            continue  # a window: the screenshot is the same scene, drawn
        if "--screenshot" in command:
            need_gl()
        argv = [ecs_anim, *shlex.split(command)[1:]]
        done = subprocess.run(argv, cwd=root, capture_output=True, text=True, timeout=300,
                              check=False)
        assert done.returncode == 0, f"{command}\n{done.stdout[-1500:]}\n{done.stderr[-1500:]}"
        outputs.append(done.stdout + done.stderr)
    imported, ran, shot = outputs
    assert "cmu_walk_120hz_adelaide.nmo: 343 frames at 120 fps, preset cmu_motionbuilder" in imported
    header = next(line for line in ran.splitlines() if "slide max mm/fr" in line)
    row = next(line.split() for line in ran.splitlines() if line.strip().startswith("mine "))
    assert header.split()[1:6] == ["float", "mm", "penetr.", "mm", "slide"], header
    floating, penetration, sliding = (float(v) for v in row[1:4])
    assert floating == 0.0 and penetration == 0.0 and sliding == 0.0, ran  # as the README says
    assert "0.000 mm of each" in recipe
    report = (root / "out" / "mine" / "report.json").read_text(encoding="utf-8")
    assert '"ground_penetration_mm_max": 0.0' in report
    assert '"max": 0.0' in report  # foot sliding, mm per frame
    assert (root / "out" / "mine" / "played" / "mine.glb").is_file()
    assert (root / "out" / "mine" / "stairs.png").is_file(), shot


@pytest.mark.parametrize("page", sorted(p.name for p in (REPO / "docs").glob("*.md")))
def test_every_docs_page_is_listed_in_the_docs_index(page: str):
    if page != "README.md":
        assert f"({page})" in (REPO / "docs" / "README.md").read_text(encoding="utf-8")


#: A figure about compiling the kernels ("compiles ... in about 48 s"): one page keeps them.
COMPILE_FIGURE = re.compile(r"compil[a-z]*[^.]{0,60}?\d+(?:\.\d)? ?s\b", re.IGNORECASE)


def test_the_compile_figures_live_on_one_page():
    """Two pages once quoted two different compile costs; now others link to the one."""
    texts = {p.relative_to(REPO).as_posix(): p.read_text(encoding="utf-8")
             for p in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]}
    quoting = sorted(name for name, text in texts.items() if COMPILE_FIGURE.search(text))
    assert quoting == ["docs/performance.md"]


#: A file of the repository a page names: a module, a test, an example, a scenario.
NAMED_FILE = re.compile(r"\b((?:ecs_anim|components|systems|tests|examples|scenarios)/[\w/]*\.(?:py|yaml|bvh))\b")


def test_every_file_the_docs_name_exists():
    """The package moved into subpackages and the tests into folders: a page must not send a
    reader to a file that is no longer there."""
    pages = [REPO / "README.md", REPO / "examples" / "README.md",
             *sorted((REPO / "docs").glob("*.md"))]
    missing = sorted({f"{page.relative_to(REPO)}: {name}" for page in pages
                      for name in NAMED_FILE.findall(page.read_text(encoding="utf-8"))
                      if not (REPO / name).exists()})
    assert missing == []
