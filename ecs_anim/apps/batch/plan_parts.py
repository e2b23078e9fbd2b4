"""A plan's parts read from text and files: a body (preset, morphology file or
``stature_<m>``), a grounds file, a scenario template, clip names, globs and folders, and the
list of formats. Shared by the command line and the manifest (:mod:`.manifest`).
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from ecs_anim.apps.batch.job_hash import files_digest
from ecs_anim.apps.batch.plan import FORMATS, RESERVED, Body, NamedGround, Template
from ecs_anim.core.errors import EcsAnimError, InputError, did_you_mean, quoted
from ecs_anim.core.files import MAX_NAME_LENGTH, NAME_PATTERN
from ecs_anim.core.morphology import PRESET_SPECS, Morphology, load_morphology_yaml

#: Clip files a batch reads, and what a folder given as a clip contributes.
CLIP_SUFFIXES = (".bvh", ".c3d", ".fbx", ".trc", ".amc", ".nmo")
#: The clip types, as messages name them.
CLIP_TYPES = ", ".join(CLIP_SUFFIXES[:-1]) + " or " + CLIP_SUFFIXES[-1]


def _check_name(name: str, what: str) -> str | None:
    """Why ``name`` cannot name output files, or None."""
    if not NAME_PATTERN.fullmatch(name):  # bodies and grounds name files, as scenario names
        return f"{quoted(name)}: a {what} name names files: letters, digits, _ . - (not starting with .)"
    if len(name) > MAX_NAME_LENGTH:
        return f"a {what} name has at most {MAX_NAME_LENGTH} characters, got {len(name)}"
    return None


def stature_name(stature_m: float, sex: str = "male", proportions: str = "adult") -> str:
    """``stature_1.35`` (``_female``, ``_child`` appended when not the default)."""
    return f"stature_{stature_m:.2f}" + ("" if sex == "male" else f"_{sex}") + \
        ("" if proportions == "adult" else f"_{proportions}")


def body_from_text(text: str, base: Path = Path("."), inputs: list[str] | None = None) -> Body:
    """A body given as text: a preset, a morphology YAML file (named by its stem; relative
    paths from ``base``; appended to ``inputs`` when given) or ``stature_<metres>`` (adult
    proportions)."""
    if text in PRESET_SPECS:
        return Body(text, Morphology.preset(text))
    if text.lower().endswith((".yaml", ".yml")):
        path = Path(text) if Path(text).is_absolute() else base / text
        if not path.is_file():
            raise InputError(path, "no such morphology file")
        problem = _check_name(path.stem, "body")
        if problem:
            raise InputError(path, problem)
        if inputs is not None:
            inputs.append(str(path))
        return Body(path.stem, load_morphology_yaml(path))
    match = re.fullmatch(r"stature_([0-9]+(?:\.[0-9]+)?)", text)
    if match:
        stature = float(match[1])
        if not 0.3 <= stature <= 3.0:
            raise EcsAnimError(f"body {text}: a stature from 0.3 to 3.0 m")
        name = stature_name(stature)
        return Body(name, Morphology.from_stature(stature, name=name))
    hint = did_you_mean(text, list(PRESET_SPECS), parenthesized=True)
    raise EcsAnimError(f"body {quoted(text)}: not a preset{hint}, a .yaml morphology or "
                       f"stature_<m>; presets: {', '.join(PRESET_SPECS)}")


def yaml_reader(path: str | Path) -> Any:
    """The scenario loader's YAML reader for ``path`` (its errors say ``file:line:``)."""
    from ecs_anim.scenario import YamlReader

    return YamlReader(str(path))


def read_named_grounds(r: Any, node: yaml.Node, where: str) -> list[NamedGround]:
    """``grounds: {name: ground, ...}`` in the scenario ground syntax (docs/scenarios.md)."""
    from ecs_anim.scenario import read_ground

    if not isinstance(node, yaml.MappingNode) or not node.value:
        raise r.fail(node, where, "expected a mapping name: {type: plane|slope|stairs|bumps|grid|"
                                  "combined, ...}")
    grounds: list[NamedGround] = []
    for key_node, value in node.value:
        name = r.string(key_node, where)
        problem = _check_name(name, "ground")
        if problem:
            raise r.fail(key_node, f"{where}.{name}", problem)
        if any(g.name == name for g in grounds):
            raise r.fail(key_node, f"{where}.{name}", "given twice")
        grounds.append(NamedGround(name, read_ground(r, value, f"{where}.{name}")))
    return grounds


def load_grounds(path: str | Path) -> list[NamedGround]:
    """A grounds file (``--grounds``): ``grounds: {name: ground, ...}``."""
    from ecs_anim.scenario import read_tree

    r = yaml_reader(path)
    root = read_tree(Path(path), "grounds", "the grounds file")
    top = r.mapping(root, "", {"grounds": True})
    return read_named_grounds(r, top["grounds"], "grounds")


def load_template(path: str | Path) -> Template:
    """A scenario with exactly one character and no triggers: every job takes its fps,
    duration, ground (when the batch names none), queued motions, placement, constraints and
    COM settings; the clip and the body replace the character's motion and morphology."""
    from ecs_anim.scenario import load_scenario

    scenario = load_scenario(path)
    if len(scenario.characters) != 1:
        raise InputError(path, f"a batch template has exactly one character, found "
                               f"{len(scenario.characters)}")
    if scenario.triggers:
        raise InputError(path, "a batch template's triggers: are not supported (a job plays one "
                               "clip on one body); remove them")
    character = scenario.characters[0]
    if any(k.target_character not in (None, character.name) for k in character.constraints):
        raise InputError(path, "a batch template's constraints aim at the world or its own body")
    return Template(str(path), scenario.fps, scenario.duration_s, scenario.ground,
                    dict(scenario.motions), character, files_digest(scenario.input_files),
                    tuple(str(f) for f in scenario.input_files))


def expand_clips(patterns: Sequence[str], base: Path = Path(".")) -> list[Path]:
    """Clip files from names, globs and folders (a folder gives its files of the
    :data:`CLIP_SUFFIXES`: an .amc's skeleton is found beside it), in the order given, each once; a pattern matching no clip is an error, and so are two clips
    with one stem (their outputs would share a folder)."""
    found: list[Path] = []
    for pattern in patterns:
        full = pattern if Path(pattern).is_absolute() else str(base / pattern)
        if glob.has_magic(pattern):
            matches = sorted(Path(p) for p in glob.glob(full, recursive=True))
            matches = [p for p in matches if p.suffix.lower() in CLIP_SUFFIXES and p.is_file()]
            if not matches:
                raise EcsAnimError(f"{pattern}: matches no {CLIP_TYPES} file")
        elif Path(full).is_dir():
            matches = sorted(p for p in Path(full).iterdir()
                             if p.suffix.lower() in CLIP_SUFFIXES and p.is_file())
            if not matches:
                raise EcsAnimError(f"{pattern}: a folder with no {CLIP_TYPES} file")
        else:
            path = Path(full)
            if not path.is_file():
                raise EcsAnimError(f"{pattern}: no such clip")
            if path.suffix.lower() not in CLIP_SUFFIXES:
                raise EcsAnimError(f"{pattern}: unsupported clip type {path.suffix!r} (expected "
                                   f"{CLIP_TYPES})")
            matches = [path]
        for path in matches:
            if any(os.path.realpath(path) == os.path.realpath(p) for p in found):
                continue
            twin = next((p for p in found if p.stem == path.stem), None)
            if twin is not None:
                raise EcsAnimError(f"{path}: has the same name as {twin}; both would be written "
                                   f"to {path.stem}/")
            if path.stem.startswith("."):
                raise EcsAnimError(f"{path}: a clip's name names its output folder: it may not "
                                   "start with '.'")
            if path.stem.lower() in RESERVED:
                raise EcsAnimError(f"{path}: a clip's name names its output folder, and "
                                   f"{path.stem} is the batch's own file; rename the clip")
            found.append(path)
    if not found:
        raise EcsAnimError("batch: give clips (files, globs or folders) or --manifest FILE.yaml")
    return found


def parse_formats(text: str) -> tuple[str, ...]:
    """``bvh,npz,glb`` -> the formats in that order; unknown or repeated ones are errors."""
    items = [t.strip().lower().lstrip(".") for t in text.split(",") if t.strip()]
    for item in items:
        if item not in FORMATS:
            raise EcsAnimError(f"--formats {text}: unknown format {quoted(item)} (expected "
                               f"{', '.join(FORMATS)})")
    if not items or len(set(items)) != len(items):
        raise EcsAnimError(f"--formats {text}: give each of {', '.join(FORMATS)} at most once")
    return tuple(items)
