"""The package's shape (DESIGN §10): subpackages in layers whose imports only go downward, no
import circle, no module reaching into another's private names, and a public surface of three
namespaces (``ecs_anim``, ``ecs_anim.components``, ``ecs_anim.systems``) for the docs and
examples.

Every import counts, at the top of a module or inside a function, except those under
``if TYPE_CHECKING:`` (never run: annotations only)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from conftest import REPO

#: Each subpackage's layer: a module may import from its own layer or a lower one.
LAYERS = {"core": 0, "motion": 1, "io": 2, "solver": 3, "components": 3, "runtime": 4,
          "systems": 4, "scenario": 5, "apps": 6}
#: Where each installed package's source lives in the repository (pyproject's package-dir).
ROOTS = {"ecs_anim": REPO / "ecs_anim", "ecs_anim.components": REPO / "components",
         "ecs_anim.systems": REPO / "systems"}
PUBLIC = ("ecs_anim", "ecs_anim.components", "ecs_anim.systems")


def modules() -> dict[str, Path]:
    found = {}
    for package, root in ROOTS.items():
        for path in root.rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join([package, *parts])] = path
    return found


def imports_of(name: str, path: Path, known: dict[str, Path]) -> list[tuple[str, str, int]]:
    """(module imported, the name taken from it or "", line) of every import run by ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped = {id(node) for branch in ast.walk(tree)
               if isinstance(branch, ast.If) and "TYPE_CHECKING" in ast.unparse(branch.test)
               for statement in branch.body for node in ast.walk(statement)}
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            out += [(a.name, "", node.lineno) for a in node.names if a.name in known]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                if f"{base}.{alias.name}" in known:
                    out.append((f"{base}.{alias.name}", "", node.lineno))
                elif base in known:
                    out.append((base, alias.name, node.lineno))
    return out


def layer(name: str) -> int | None:
    parts = name.split(".")
    return LAYERS.get(parts[1]) if len(parts) > 1 else None


GRAPH = {name: imports_of(name, path, modules()) for name, path in modules().items()}


def test_every_module_is_in_a_layer():
    assert [n for n in GRAPH if n != "ecs_anim" and layer(n) is None] == []


def test_imports_only_go_downward():
    upward = [f"{name} (layer {layer(name)}) imports {target} (layer {layer(target)}) at line {line}"
              for name, found in GRAPH.items() if name != "ecs_anim"
              for target, _, line in found
              if layer(target) is not None and layer(target) > layer(name)]  # type: ignore[operator]
    assert upward == []


def test_no_module_imports_another_ones_private_names():
    private = [f"{name}:{line} takes {taken} from {target}"
               for name, found in GRAPH.items() for target, taken, line in found
               if taken.startswith("_") and target != name]
    assert private == []


def test_there_is_no_import_circle():
    edges = {name: {target for target, _, _ in found if target in GRAPH} for name, found in GRAPH.items()}
    circles, state = [], dict.fromkeys(edges, 0)  # 0 unseen, 1 on the path, 2 done

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(edges[node]):
            if state[nxt] == 1:
                circles.append(" -> ".join(path[path.index(nxt):] + [nxt]))
            elif state[nxt] == 0:
                visit(nxt, path + [nxt])
        state[node] = 2

    for start in sorted(edges):
        if state[start] == 0:
            visit(start, [start])
    assert circles == []


def test_a_module_that_imports_itself_through_its_package_is_caught():
    """The walk resolves relative imports (``from .x import y``) like Python does."""
    found = imports_of("ecs_anim.core.fake", REPO / "ecs_anim" / "core" / "skeleton.py",
                       {"ecs_anim.core.skeleton": Path()})
    assert found == []  # skeleton imports nothing of ours
    assert layer("ecs_anim.apps.cli.main") == 6 and layer("ecs_anim.core.skeleton") == 0


IMPORT_LINE = re.compile(r"^\s*(?:from\s+(ecs_anim[\w.]*)\s+import|import\s+(ecs_anim[\w.]*))", re.M)


def test_docs_readme_and_examples_import_only_the_public_namespaces():
    texts = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")),
             *sorted((REPO / "examples").glob("*.py"))]
    outside = [f"{path.relative_to(REPO)}: {m.group(1) or m.group(2)}"
               for path in texts for m in IMPORT_LINE.finditer(path.read_text(encoding="utf-8"))
               if (m.group(1) or m.group(2)) not in PUBLIC]
    assert outside == []
