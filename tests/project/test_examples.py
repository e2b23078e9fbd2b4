"""Every ``examples/*.py`` runs as a user runs it: its own process, this Python, from another
folder than the repository, and exits 0 printing at least one measured figure (a number with a
unit). ``target_follow.py`` also fails, as it says it does, when its point is out of reach."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

EXAMPLES = sorted((REPO / "examples").glob("*.py"))
#: A figure: a number followed by a unit (mm, m, m/s, s, Hz, deg, %).
FIGURE = re.compile(r"\d+(?:\.\d+)?\s?(?:mm|m/s|m|s|Hz|deg|%)(?![a-zA-Z])")
TIMEOUT_S = 300


def run_example(path: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(path), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=TIMEOUT_S)


def test_the_examples_are_listed_in_their_readme():
    assert EXAMPLES, "no examples/*.py"
    listed = (REPO / "examples" / "README.md").read_text(encoding="utf-8")
    for path in EXAMPLES:
        assert f"]({path.name})" in listed, f"examples/README.md does not list {path.name}"


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_runs_and_prints_a_figure(path: Path, tmp_path: Path):
    done = run_example(path, cwd=tmp_path)
    assert done.returncode == 0, (f"examples/{path.name} exited {done.returncode}:\n"
                                  f"{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    assert FIGURE.search(done.stdout), f"examples/{path.name} printed no figure:\n{done.stdout}"


def test_target_follow_keeps_the_wrist_on_the_point_and_fails_out_of_reach(tmp_path: Path):
    path = REPO / "examples" / "target_follow.py"
    done = run_example(path, "--seconds", "3", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    rows = [line.split() for line in done.stdout.splitlines() if re.fullmatch(r"\s+\d+\s+\S+\s+\S+", line)]
    assert [int(r[0]) for r in rows] == [1, 2, 3]
    assert max(float(v) for r in rows for v in r[1:]) < 0.5, done.stdout  # mm, every second
    far = run_example(path, "--seconds", "1", "--radius-m", "0.8", cwd=tmp_path)
    assert far.returncode == 1, far.stdout
    worst = re.search(r"worst (\d+\.\d+) mm", far.stdout)
    assert worst is not None and float(worst.group(1)) > 100.0, far.stdout  # out of reach
    bad = run_example(path, "--seconds", "-1", cwd=tmp_path)
    assert bad.returncode == 2 and "--seconds must be in (0, 600]" in bad.stderr
