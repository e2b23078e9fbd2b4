"""A batch manifest (``--manifest FILE.yaml``): clips, bodies (a stature range among them),
grounds, template, formats, out, seconds and the rig the files go onto, validated with
``file:line:`` errors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ecs_anim.apps.batch.plan import Body
from ecs_anim.apps.batch.plan_parts import (
    body_from_text,
    expand_clips,
    load_template,
    parse_formats,
    read_named_grounds,
    stature_name,
    yaml_reader,
)
from ecs_anim.core.errors import EcsAnimError, InputError, quoted
from ecs_anim.core.morphology import Morphology

#: ``statures: {count}`` is bounded, as the jobs are (:data:`~ecs_anim.apps.batch.plan.MAX_JOBS`),
#: so a typo cannot plan a year of work.
MAX_STATURES = 1_000


def _manifest_body(r: Any, node: yaml.Node, where: str, base: Path,
                   inputs: list[str] | None = None) -> list[Body]:
    """One ``bodies:`` item: a name (see :func:`~ecs_anim.apps.batch.plan_parts.body_from_text`) or
    ``{statures: {from_m, to_m, count}, proportions: adult|child, sex: male|female}``."""
    if isinstance(node, yaml.ScalarNode):
        text = r.string(node, where)
        if text.lower().endswith((".yaml", ".yml")):
            path = Path(text) if Path(text).is_absolute() else base / text
            if not path.is_file():
                raise r.fail(node, where, f"no such morphology file {quoted(str(path))}")
        try:
            return [body_from_text(text, base, inputs)]
        except InputError:
            raise
        except EcsAnimError as exc:
            raise r.fail(node, where, str(exc)) from None
    keys = r.mapping(node, where, {"statures": True, "proportions": False, "sex": False})
    sk = r.mapping(keys["statures"], f"{where}.statures", {"from_m": True, "to_m": True,
                                                             "count": True})
    low = r.number(sk["from_m"], f"{where}.statures.from_m", 0.3, 3.0, "m")
    high = r.number(sk["to_m"], f"{where}.statures.to_m", 0.3, 3.0, "m")
    count = r.integer(sk["count"], f"{where}.statures.count", 1, MAX_STATURES)
    if count > 1 and high <= low:
        raise r.fail(sk["to_m"], f"{where}.statures.to_m", f"expected more than from_m ({low:g} m) "
                     "for several statures")
    choices = {"sex": ("male", "female"), "proportions": ("adult", "child")}
    given = {}
    for key, allowed in choices.items():
        value = r.string(keys[key], f"{where}.{key}") if key in keys else allowed[0]
        if value not in allowed:
            raise r.fail(keys[key], f"{where}.{key}", f"expected {' or '.join(allowed)}, found "
                                                      f"{quoted(value)}")
        given[key] = value
    statures = np.linspace(low, high, count) if count > 1 else np.array([low])
    names = [stature_name(float(s), given["sex"], given["proportions"]) for s in statures]
    if len(set(names)) < len(names):
        raise r.fail(keys["statures"], f"{where}.statures", f"{count} statures from {low:g} to "
                     f"{high:g} m repeat a name at 1 cm ({names[0]}, ...); give fewer")
    return [Body(n, Morphology.from_stature(float(s), given["sex"], given["proportions"], name=n))
            for n, s in zip(names, statures, strict=True)]


MANIFEST_KEYS = {"clips": True, "bodies": True, "grounds": False, "template": False,
                 "formats": False, "out": False, "seconds": False, "onto": False}


def load_manifest(path: str | Path) -> dict[str, Any]:
    """A manifest (``--manifest``), validated with ``file:line:`` errors; paths in it are
    relative to its folder. Returns the plan's parts: clips, bodies, grounds, template, formats,
    out, seconds, onto ((rig path, map)) (absent keys absent), and inputs (the morphology files
    read)."""
    from ecs_anim.scenario import read_tree

    path = Path(path)
    base = path.parent
    r = yaml_reader(path)
    root = read_tree(path, "batch manifest", "the manifest")
    top = r.mapping(root, "", MANIFEST_KEYS)
    inputs: list[str] = []
    parts: dict[str, Any] = {"inputs": inputs}
    patterns = [r.string(n, f"clips[{i}]") for i, n in enumerate(r.sequence(top["clips"], "clips"))]
    try:
        parts["clips"] = expand_clips(patterns, base)
    except EcsAnimError as exc:
        raise r.fail(top["clips"], "clips", str(exc)) from None
    body_nodes = r.sequence(top["bodies"], "bodies")
    if not body_nodes:
        raise r.fail(top["bodies"], "bodies", "expected at least one body")
    bodies: list[Body] = []
    for i, node in enumerate(body_nodes):
        for body in _manifest_body(r, node, f"bodies[{i}]", base, inputs):
            if any(b.name == body.name for b in bodies):
                raise r.fail(node, f"bodies[{i}]", f"a body named {body.name!r} is given twice")
            bodies.append(body)
    parts["bodies"] = bodies
    if "grounds" in top:
        parts["grounds"] = read_named_grounds(r, top["grounds"], "grounds")
    for key in ("template", "out"):
        if key in top:
            given = r.string(top[key], key)
            parts[key] = Path(given) if Path(given).is_absolute() else base / given
    if "template" in parts:
        if not parts["template"].is_file():
            raise r.fail(top["template"], "template", f"no such scenario file "
                                                      f"{quoted(str(parts['template']))}")
        parts["template"] = load_template(parts["template"])
    if "formats" in top:
        names = [r.string(n, f"formats[{i}]") for i, n in enumerate(r.sequence(top["formats"], "formats"))]
        try:
            parts["formats"] = parse_formats(",".join(names))
        except EcsAnimError as exc:
            raise r.fail(top["formats"], "formats", str(exc).split(": ", 1)[1]) from None
    if "seconds" in top:
        parts["seconds"] = r.number(top["seconds"], "seconds", 1e-3, 86400.0, "s")
    if "onto" in top:
        parts["onto"] = _manifest_onto(r, top["onto"], base)
    return parts


def _manifest_onto(r: Any, node: yaml.Node, base: Path) -> tuple[str, str | None]:
    """``onto:`` a rig file, or ``{rig: FILE, map: PRESET|FILE.yaml}``: (rig path, map), files
    relative to the manifest's folder."""
    def relative(text: str) -> str:
        return text if Path(text).is_absolute() else str(base / text)

    if isinstance(node, yaml.ScalarNode):
        rig, map_spec = r.string(node, "onto"), None
    else:
        keys = r.mapping(node, "onto", {"rig": True, "map": False})
        rig = r.string(keys["rig"], "onto.rig")
        map_spec = r.string(keys["map"], "onto.map") if "map" in keys else None
        if map_spec is not None and Path(map_spec).suffix.lower() in (".yaml", ".yml"):
            map_spec = relative(map_spec)
    if not Path(relative(rig)).is_file():
        raise r.fail(node, "onto", f"no such rig file {quoted(relative(rig))}")
    return relative(rig), map_spec
