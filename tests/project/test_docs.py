"""Every ```python block of docs/*.md and of the README runs as written.

The blocks of one file run in order in one namespace (a page may build on its earlier blocks),
with the repository root as the working folder, as a reader pastes them into Python there. A
failure names the file and the line of the block's first code line; the traceback's lines are
the Markdown file's own. Nothing is skipped silently: every block of the README (it has none
now: its examples moved to docs/quickstart.md) runs here. docs/quickstart.md's "From Python"
blocks run here with the other pages' and again, with their printed output checked, in
``tests/runtime/test_hardening_pipeline.py::test_the_readme_python_examples_run``; this file
checks that that test is still there and still reads that section.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import REPO

FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.DOTALL | re.MULTILINE)
#: The page and section whose blocks another test also runs (and checks their output).
PAGE_RUN_ELSEWHERE, SECTION_RUN_ELSEWHERE = "docs/quickstart.md", "## From Python"
RUN_ELSEWHERE_BY = ("tests/runtime/test_hardening_pipeline.py",
                    "def test_the_readme_python_examples_run")


def python_blocks(text: str) -> list[tuple[int, str]]:
    """Each ```python block of a Markdown text: (line of its first code line, its code)."""
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in FENCE.finditer(text)]


#: The pages with Python in them (a page of YAML and shell alone has nothing to run here).
DOCS = [p for p in sorted((REPO / "docs").glob("*.md"))
        if python_blocks(p.read_text(encoding="utf-8"))]


def run_blocks(path: Path, blocks: list[tuple[int, str]], monkeypatch: pytest.MonkeyPatch,
               root: Path = REPO) -> None:
    """Run ``blocks`` of ``path`` in order in one namespace, from ``root`` (the repository)."""
    monkeypatch.chdir(root)
    shown = path.relative_to(root)
    namespace: dict[str, object] = {"__name__": f"docs_{path.stem}"}
    for line, code in blocks:
        # Padded so that the traceback's line numbers are the Markdown file's.
        compiled = compile("\n" * (line - 1) + code, str(shown), "exec")
        try:
            exec(compiled, namespace)
        except BaseException as exc:  # SystemExit too: a block must not end the session
            raise AssertionError(f"{shown}:{line}: the ```python block starting here failed: "
                                 f"{type(exc).__name__}: {exc}") from exc


def section_blocks(path: Path, heading: str) -> list[tuple[int, str]]:
    """The ```python blocks of ``path`` under ``heading``, up to the next ``## `` heading."""
    text = path.read_text(encoding="utf-8")
    start = text.index(f"\n{heading}\n")
    end = text.find("\n## ", start + 1)
    end = len(text) if end < 0 else end
    start_line, end_line = text.count("\n", 0, start) + 1, text.count("\n", 0, end) + 1
    return [(line, code) for line, code in python_blocks(text) if start_line <= line <= end_line]


def test_there_are_docs_with_python_blocks_and_none_is_missed():
    assert "api.md" in [p.name for p in DOCS]
    assert len(python_blocks((REPO / "docs" / "api.md").read_text(encoding="utf-8"))) >= 15
    # A fence this test would not recognise (indented, ```py, ``` python) would go unrun.
    for path in [*sorted((REPO / "docs").glob("*.md")), REPO / "README.md"]:
        text = path.read_text(encoding="utf-8")
        opened = [i + 1 for i, line in enumerate(text.splitlines())
                  if re.match(r"\s*```\s*py", line, re.IGNORECASE)]
        assert len(opened) == len(python_blocks(text)), (
            f"{path.relative_to(REPO)}:{opened}: a Python fence not at the line's start or not "
            "spelt ```python (it would not be run)")


def test_the_api_page_imports_only_what_the_package_exports():
    """docs/api.md is the public API: its examples import from ``ecs_anim`` itself, and only
    names in ``ecs_anim.__all__``."""
    import ast

    import ecs_anim

    for line, code in python_blocks((REPO / "docs" / "api.md").read_text(encoding="utf-8")):
        for node in ast.walk(ast.parse(code)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ecs_anim"):
                where = f"docs/api.md:{line + node.lineno - 1}"
                assert node.module == "ecs_anim", f"{where}: imports from {node.module}"
                missing = [a.name for a in node.names if a.name not in ecs_anim.__all__]
                assert not missing, f"{where}: {missing} not in ecs_anim.__all__"


@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_every_python_block_of_the_docs_runs(path: Path, monkeypatch: pytest.MonkeyPatch):
    run_blocks(path, python_blocks(path.read_text(encoding="utf-8")), monkeypatch)


def test_the_readmes_python_blocks_run_here_or_in_the_test_that_checks_their_output(
        monkeypatch: pytest.MonkeyPatch):
    # The README's blocks (none since its examples moved to docs/), every one, run here.
    run_blocks(REPO / "README.md", python_blocks((REPO / "README.md").read_text(encoding="utf-8")),
               monkeypatch)
    # The quickstart's "From Python" blocks: run by the docs-page test above, and by the test
    # that checks their printed output, which must still be there and read that section.
    page = REPO / PAGE_RUN_ELSEWHERE
    assert page in DOCS, f"{PAGE_RUN_ELSEWHERE} has no ```python block"
    elsewhere = section_blocks(page, SECTION_RUN_ELSEWHERE)
    assert len(elsewhere) == 4, (
        f"{PAGE_RUN_ELSEWHERE} {SECTION_RUN_ELSEWHERE!r}: {len(elsewhere)} ```python blocks, "
        "4 expected (tests/runtime/test_hardening_pipeline.py, "
        "tests/solver/test_solver_budget.py and tests/runtime/test_update_rate.py run them)")
    path, test = RUN_ELSEWHERE_BY
    source = (REPO / path).read_text(encoding="utf-8")
    assert test in source, (
        f"{path} no longer runs {PAGE_RUN_ELSEWHERE}'s {SECTION_RUN_ELSEWHERE!r} blocks: "
        "check their output here")
    body = source.split(test, 1)[1].split("\ndef ", 1)[0]
    assert '"quickstart.md"' in body and f'"{SECTION_RUN_ELSEWHERE}"' in body, (
        f"{path}::{test.removeprefix('def ')} no longer reads {PAGE_RUN_ELSEWHERE}'s "
        f"{SECTION_RUN_ELSEWHERE!r}")


def test_a_failing_block_is_named_by_file_and_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    page = tmp_path / "page.md"
    page.write_text("# A page\n\n```python\nx = 1\n```\n\ntext\n\n```python\ny = x + 1\n"
                    "raise ValueError(y)\n```\n", encoding="utf-8")
    blocks = python_blocks(page.read_text(encoding="utf-8"))
    assert blocks == [(4, "x = 1\n"), (10, "y = x + 1\nraise ValueError(y)\n")]
    with pytest.raises(AssertionError, match=r"^page\.md:10: the ```python block starting here "
                       r"failed: ValueError: 2$") as failure:
        run_blocks(page, blocks, monkeypatch, root=tmp_path)
    assert failure.value.__cause__ is not None
    assert failure.value.__cause__.__traceback__ is not None
    frames = [f for f in _frames(failure.value.__cause__.__traceback__) if f[0] == "page.md"]
    assert frames == [("page.md", 11)]  # the raise, at its line of the Markdown file


def _frames(tb: object) -> list[tuple[str, int]]:
    import traceback

    return [(f.filename, f.lineno or 0) for f in traceback.extract_tb(tb)]  # type: ignore[arg-type]
