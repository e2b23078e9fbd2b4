"""``ecs-anim batch``: many clips played on many bodies over many grounds, in parallel.

A batch is the product clips x bodies x grounds. Each job plays one clip on one body over one
ground through the same pipeline as ``ecs-anim run`` (:func:`~ecs_anim.scenario.loader.build_simulation`
on an in-memory :class:`~ecs_anim.scenario.loader.Scenario`, metrics by
:class:`~ecs_anim.runtime.metrics.MetricsRecorder`), and writes ``DIR/<clip>/<body>[_<ground>].<format>``.

Who does what:

* the driver (this process) plans the jobs, skips those already done (a stamp beside the
  outputs holds a content hash of clip, body, ground, template, formats and project version),
  and writes every file, each atomically (:func:`~ecs_anim.core.files.atomic_output`), the stamp
  last: a job killed half-way has no stamp and is done again, so its outputs end whole;
* the workers (a local process pool, or Ray tasks) import each clip once and run jobs; they
  return the files' bytes, so workers on other machines need no shared file system, and the
  local and Ray engines produce the same bytes from the same function.

Finally ``DIR/metrics.json``, ``DIR/metrics.csv`` (one row per job, the scalar fields of
:data:`CSV_FIELDS` then one ``constraint:<name>_mm`` column per stored constraint) and
``DIR/report.html`` (:func:`ecs_anim.apps.batch.report.write_report`).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import glob
import hashlib
import io
import json
import logging
import math
import multiprocessing
import os
import pickle
import re
import sys
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, did_you_mean, quoted
from ecs_anim.core.files import MAX_NAME_LENGTH, NAME_PATTERN
from ecs_anim.core.ground import Ground, Plane
from ecs_anim.core.morphology import PRESET_SPECS, Morphology, load_morphology_yaml
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.runtime import kernels

F64 = NDArray[np.float64]

#: Output formats a batch writes (``--formats``).
FORMATS = ("bvh", "npz", "glb")
DEFAULT_FORMATS = ("bvh", "npz")
#: Clip files a batch reads, and what a folder given as a clip contributes.
CLIP_SUFFIXES = (".bvh", ".c3d", ".nmo")
#: Written first into a batch folder: a folder without it that holds anything is not ours.
BATCH_MARKER = ".ecs-anim-batch.json"
#: The batch's own files in its folder: no clip may be named so (its folder would be theirs).
RESERVED = ("metrics.csv", "metrics.json", "report.html")
#: Beside each job's outputs, written after them: the job's input hash and its record.
STAMP_SUFFIX = ".ecs-anim-job.json"
#: ``statures: {count}`` and the whole product are bounded so a typo cannot plan a year of work.
MAX_STATURES = 1_000
MAX_JOBS = 1_000_000
#: Foot-skate ratio (the motion-synthesis literature's definition, e.g. PhysDiff, GMD): a frame
#: skates when a foot (its toe joint, the ball of the foot) is under this height above the
#: ground and moves horizontally faster than :data:`SKATE_STEP_M` per 1/30 s.
SKATE_HEIGHT_M = 0.05
SKATE_STEP_M = 0.025
SKATE_REFERENCE_HZ = 30.0
#: The scalar columns of ``metrics.csv``, in order (then ``constraint:<name>_mm``).
CSV_FIELDS = ("clip", "body", "ground", "stature_m", "frames", "status", "error", "slide_max_mm",
              "slide_mean_mm", "penetration_max_mm", "floating_max_mm", "bone_error_m",
              "com_error_mm", "foot_skate_ratio", "seconds")


def project_version() -> str:
    """The installed ecs_anim version (written into metrics.json and the batch marker)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ecs_anim")
    except PackageNotFoundError:
        return "0+unknown"


_SOURCE_DIGEST: str | None = None


def source_digest() -> str:
    """A hash of the package's own source files (every ``.py`` of ``ecs_anim`` and of the
    ``ecs_anim.components`` and ``ecs_anim.systems`` packages, wherever they are installed
    from), computed once per process: part of every job's hash, so a code change redoes jobs
    even when the version string stays."""
    global _SOURCE_DIGEST
    if _SOURCE_DIGEST is None:
        import importlib

        digest = hashlib.sha256()
        for name in ("ecs_anim", "ecs_anim.components", "ecs_anim.systems"):
            module = importlib.import_module(name)
            folder = Path(module.__file__ or "").resolve().parent
            files = sorted(folder.rglob("*.py"))
            for path in files:
                digest.update(f"{name}/{path.relative_to(folder)}".encode() + b"\0")
                digest.update(hashlib.sha256(path.read_bytes()).digest())
        _SOURCE_DIGEST = digest.hexdigest()
    return _SOURCE_DIGEST


# --------------------------------------------------------------------------------------------
# The plan: bodies, grounds, clips, an optional template, and the jobs they make.


@dataclass(frozen=True)
class Body:
    """A body a batch plays clips on; ``name`` names its output files."""

    name: str
    morphology: Morphology


@dataclass(frozen=True)
class NamedGround:
    """A ground and its name (``""`` for the default plane: no suffix on the files)."""

    name: str
    ground: Ground


@dataclass(frozen=True)
class Template:
    """What a scenario template gives every job: its rate, duration, ground (when the batch
    has none of its own), other motions (for queues) and its one character's settings."""

    path: str
    fps: float
    duration_s: float
    ground: Ground
    motions: dict[str, NormalizedMotion]
    character: Any  # scenario.CharacterSpec (its morphology and clip replaced per job)
    digest: str  # of the template file and every motion file it read
    input_files: tuple[str, ...] = ()  # the template's motion (and other) files


@dataclass(frozen=True)
class Job:
    """One clip on one body over one ground. ``stem`` is the outputs' path relative to the
    batch folder without the extension (``<clip>/<body>[_<ground>]``)."""

    clip_path: str
    clip: str
    body: Body
    ground: NamedGround
    formats: tuple[str, ...]
    seconds: float | None = None  # simulate this long instead of the clip's (template's) length
    template: Template | None = None

    @property
    def stem(self) -> str:
        return f"{self.clip}/{self.body.name}" + (f"_{self.ground.name}" if self.ground.name else "")

    @property
    def stamp(self) -> str:
        """The stamp's path relative to the batch folder (hidden, beside the outputs)."""
        folder, name = self.stem.split("/")
        return f"{folder}/.{name}{STAMP_SUFFIX}"

    def outputs(self) -> list[str]:
        return [f"{self.stem}.{ext}" for ext in self.formats]

    def all_outputs(self) -> list[str]:
        """The job's files in every format: a job redone or failed deletes those it no longer
        writes."""
        return [f"{self.stem}.{ext}" for ext in FORMATS]


@dataclass
class Plan:
    """What to run and where: clip paths, bodies, grounds, formats, the folder."""

    clips: list[Path]
    bodies: list[Body]
    grounds: list[NamedGround]
    formats: tuple[str, ...]
    out: Path
    template: Template | None = None
    seconds: float | None = None
    inputs: list[str] = field(default_factory=list)  # every file read: never an output

    def jobs(self) -> list[Job]:
        return [Job(str(c), c.stem, b, g, self.formats, self.seconds, self.template)
                for c in self.clips for b in self.bodies for g in self.grounds]


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


def _reader(path: str | Path) -> Any:
    from ecs_anim.scenario import YamlReader

    return YamlReader(str(path))


def _manifest_body(r: Any, node: yaml.Node, where: str, base: Path,
                   inputs: list[str] | None = None) -> list[Body]:
    """One ``bodies:`` item: a name (see :func:`body_from_text`) or
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


def _grounds_mapping(r: Any, node: yaml.Node, where: str) -> list[NamedGround]:
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

    r = _reader(path)
    root = read_tree(Path(path), "grounds", "the grounds file")
    top = r.mapping(root, "", {"grounds": True})
    return _grounds_mapping(r, top["grounds"], "grounds")


def load_template(path: str | Path) -> Template:
    """A scenario with exactly one character: every job takes its fps, duration, ground (when
    the batch names none), queued motions, placement, constraints and COM settings; the clip
    and the body replace the character's motion and morphology."""
    from ecs_anim.scenario import load_scenario

    scenario = load_scenario(path)
    if len(scenario.characters) != 1:
        raise InputError(path, f"a batch template has exactly one character, found "
                               f"{len(scenario.characters)}")
    character = scenario.characters[0]
    if any(k.target_character not in (None, character.name) for k in character.constraints):
        raise InputError(path, "a batch template's constraints aim at the world or its own body")
    return Template(str(path), scenario.fps, scenario.duration_s, scenario.ground,
                    dict(scenario.motions), character, _files_digest(scenario.input_files),
                    tuple(str(f) for f in scenario.input_files))


def expand_clips(patterns: Sequence[str], base: Path = Path(".")) -> list[Path]:
    """Clip files from names, globs and folders (a folder gives its .bvh, .c3d and .nmo files),
    in the order given, each once; a pattern matching no clip is an error, and so are two clips
    with one stem (their outputs would share a folder)."""
    found: list[Path] = []
    for pattern in patterns:
        full = pattern if Path(pattern).is_absolute() else str(base / pattern)
        if glob.has_magic(pattern):
            matches = sorted(Path(p) for p in glob.glob(full, recursive=True))
            matches = [p for p in matches if p.suffix.lower() in CLIP_SUFFIXES and p.is_file()]
            if not matches:
                raise EcsAnimError(f"{pattern}: matches no .bvh, .c3d or .nmo file")
        elif Path(full).is_dir():
            matches = sorted(p for p in Path(full).iterdir()
                             if p.suffix.lower() in CLIP_SUFFIXES and p.is_file())
            if not matches:
                raise EcsAnimError(f"{pattern}: a folder with no .bvh, .c3d or .nmo file")
        else:
            path = Path(full)
            if not path.is_file():
                raise EcsAnimError(f"{pattern}: no such clip")
            if path.suffix.lower() not in CLIP_SUFFIXES:
                raise EcsAnimError(f"{pattern}: unsupported clip type {path.suffix!r} (expected "
                                   ".bvh, .c3d or .nmo)")
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


MANIFEST_KEYS = {"clips": True, "bodies": True, "grounds": False, "template": False,
                 "formats": False, "out": False, "seconds": False}


def load_manifest(path: str | Path) -> dict[str, Any]:
    """A manifest (``--manifest``), validated with ``file:line:`` errors; paths in it are
    relative to its folder. Returns the plan's parts: clips, bodies, grounds, template, formats,
    out, seconds (absent keys absent), and inputs (the morphology files read)."""
    from ecs_anim.scenario import read_tree

    path = Path(path)
    base = path.parent
    r = _reader(path)
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
        parts["grounds"] = _grounds_mapping(r, top["grounds"], "grounds")
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
    return parts


def plan_from_args(args: argparse.Namespace) -> Plan:
    """The plan from the command line, or from ``--manifest`` (the command line's ``--out``,
    ``--formats`` and ``--seconds`` override the manifest's)."""
    inputs: list[str] = []
    if args.manifest:
        given = [flag for flag, value in (("CLIP", args.clips), ("--bodies", args.bodies),
                                          ("--grounds", args.grounds), ("--template", args.template))
                 if value]
        if given:
            raise EcsAnimError(f"--manifest: give clips, bodies, grounds and the template in the "
                               f"manifest, not also {', '.join(given)}")
        parts = load_manifest(args.manifest)
        inputs += [args.manifest, *parts["inputs"]]
    else:
        parts = {"clips": expand_clips(args.clips or [])}
        if not args.bodies:
            raise EcsAnimError("batch: give --bodies (e.g. child,adult_male,tall) or --manifest")
        bodies: list[Body] = []
        for text in (t.strip() for t in args.bodies.split(",")):
            if not text:
                continue
            body = body_from_text(text, inputs=inputs)
            if any(b.name == body.name for b in bodies):
                raise EcsAnimError(f"--bodies: {body.name!r} is given twice")
            bodies.append(body)
        parts["bodies"] = bodies
        if args.grounds:
            parts["grounds"] = load_grounds(args.grounds)
            inputs.append(args.grounds)
        if args.template:
            parts["template"] = load_template(args.template)
    if args.out is not None:
        parts["out"] = Path(args.out)
    if "out" not in parts:
        raise EcsAnimError("batch: give --out DIR (or out: in the manifest)")
    if args.formats is not None:
        parts["formats"] = parse_formats(args.formats)
    if args.seconds is not None:
        parts["seconds"] = args.seconds
    template: Template | None = parts.get("template")
    if parts.get("seconds") is not None:
        _check_seconds(parts["seconds"], parts["clips"], template)
    grounds = parts.get("grounds") or [NamedGround("", template.ground if template else Plane())]
    bodies = parts["bodies"]
    stems: dict[str, str] = {}
    for b in bodies:
        for g in grounds:
            stem = b.name + (f"_{g.name}" if g.name else "")
            if stem in stems:
                raise EcsAnimError(f"body {b.name!r} over ground {g.name!r} and {stems[stem]} "
                                   f"both write {stem}.*; rename one")
            stems[stem] = f"body {b.name!r} over ground {g.name!r}"
    inputs += [str(c) for c in parts["clips"]]
    if template is not None:
        inputs += [template.path, *template.input_files]
    plan = Plan(parts["clips"], bodies, grounds, parts.get("formats", DEFAULT_FORMATS),
                parts["out"], template, parts.get("seconds"), inputs)
    n_jobs = len(plan.clips) * len(bodies) * len(grounds)
    if n_jobs > MAX_JOBS:
        raise EcsAnimError(f"batch: {n_jobs:,} jobs; at most {MAX_JOBS:,} in one batch")
    return plan


def _check_seconds(seconds: float, clips: Sequence[Path], template: Template | None) -> None:
    """``--seconds`` as ``run`` bounds it: at most :data:`~ecs_anim.runtime.simulation.MAX_DURATION_S`,
    and at least one tick at the template's rate, or at every clip's (read from the file's
    header where that is cheap; a clip's rate is checked again when it plays)."""
    from ecs_anim.runtime.simulation import MAX_DURATION_S

    if seconds > MAX_DURATION_S:
        raise EcsAnimError(f"--seconds {seconds:g}: at most {MAX_DURATION_S:g} s (a day) in one job")
    rates = [template.fps] if template is not None else [fps for c in clips
                                                         if (fps := _clip_fps(c)) is not None]
    for fps in rates:
        if round(seconds * fps) < 1:
            raise EcsAnimError(f"--seconds {seconds:g} is less than one tick at {fps:g} Hz")


def _clip_fps(path: Path) -> float | None:
    """A BVH clip's frame rate from its ``Frame Time:`` line, or None (other formats, or not
    found: the job checks it)."""
    if path.suffix.lower() != ".bvh":
        return None
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 20)
    except OSError:
        return None
    match = re.search(rb"Frame\s+Time\s*:\s*([0-9.eE+\-]+)", head)
    try:
        step = float(match[1]) if match else 0.0
    except ValueError:
        return None
    return 1.0 / step if step > 0 else None


# --------------------------------------------------------------------------------------------
# Content hashes.


def _canonical(value: Any) -> Any:
    """``value`` as JSON-able data that two equal inputs map to identically: dataclasses by
    type and fields, arrays by dtype, shape and a hash of their bytes, floats exactly."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return [type(value).__name__, {f.name: _canonical(getattr(value, f.name))
                                       for f in dataclasses.fields(value)}]
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value)
        return ["array", str(data.dtype), list(data.shape), hashlib.sha256(data.tobytes()).hexdigest()]
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value).hex()
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def _files_digest(paths: Sequence[str | Path]) -> str:
    digest = hashlib.sha256()
    for path in paths:
        digest.update(hashlib.sha256(Path(path).read_bytes()).digest())
    return digest.hexdigest()


def job_digest(job: Job, clip_digest: str, version: str) -> str:
    """The hash a job's stamp holds: its clip's bytes, body, ground, template, formats, length
    and ``version`` (the project version and :func:`source_digest`). Equal hashes mean equal
    outputs."""
    data = {"version": version, "clip": clip_digest, "body": _canonical(job.body),
            "ground": _canonical(job.ground), "formats": list(job.formats),
            "seconds": _canonical(job.seconds),
            "template": None if job.template is None else job.template.digest}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------------
# Work done by the workers: import a clip, run a job. Pure functions of their inputs.


def import_clip(path: str | Path) -> NormalizedMotion:
    """The motion in a clip file, read by a scenario's ``motions:`` reader
    (:func:`ecs_anim.scenario.loader.read_motion`: the importers' defaults), so a job plays what
    ``ecs-anim run`` would."""
    from ecs_anim.scenario import read_motion

    class _Clip:  # the reader read_motion reports through: a clip has no line of its own
        @staticmethod
        def fail(node: object, where: str, message: str) -> EcsAnimError:
            return EcsAnimError(message)

    return read_motion(_Clip(), None, "", Path(path), str(path))


@dataclass
class Outcome:
    """A finished job: its record (see :func:`job_record`) and its files' bytes by path
    relative to the batch folder (empty when it failed)."""

    record: dict[str, Any]
    files: dict[str, bytes] = field(default_factory=dict)


def error_text(exc: BaseException) -> str:
    """A job's one-line error: the user error as the CLI prints it, or, for a bug, its type."""
    from ecs_anim.apps.cli.args import error_line

    if isinstance(exc, (EcsAnimError, OSError)):
        return error_line(exc)
    return error_line(RuntimeError(f"internal error: {type(exc).__name__}: {exc}"))


def failed_record(job: Job, error: str, seconds: float = 0.0) -> dict[str, Any]:
    """The record of a job that failed with the one-line ``error``."""
    return {"clip": job.clip, "body": job.body.name, "ground": job.ground.name,
            "stature_m": round(job.body.morphology.stature, 4), "frames": 0, "status": "failed",
            "error": error, "duration_s": None, "slide_max_mm": None, "slide_mean_mm": None, "penetration_max_mm": None,
            "floating_max_mm": None, "bone_error_m": None, "com_error_mm": None,
            "foot_skate_ratio": None, "seconds": round(seconds, 4), "outputs": [],
            "constraint_errors_mm": {}, "contacts": {"left": [], "right": []}}


def job_scenario(job: Job, motion: NormalizedMotion) -> Any:
    """The in-memory scenario of a job: the clip (motion name = the clip's name) on the body at
    the origin, facing +x, not looping, at the clip's rate for its length; or, with a template,
    the template's character, rate and length with the clip and body swapped in."""
    from ecs_anim.components import MotionPlayer, Placement
    from ecs_anim.scenario import CharacterSpec, Scenario

    t = job.template
    if t is None:
        fps = motion.fps
        duration = motion.n_frames / motion.fps if job.seconds is None else job.seconds
        character = CharacterSpec(job.body.name, job.body.morphology,
                                  MotionPlayer(job.clip, loop=False), Placement())
        return Scenario(job.clip_path, duration, fps, {job.clip: motion}, job.ground.ground,
                        [character])
    base = t.character
    motions = dict(t.motions) | {job.clip: motion}
    character = dataclasses.replace(base, name=job.body.name, morphology=job.body.morphology,
                                    player=dataclasses.replace(base.player, clip=job.clip),
                                    constraints=[dataclasses.replace(k, target_character=None
                                                                     if k.target_character is None
                                                                     else job.body.name)
                                                 for k in base.constraints])
    ground = job.ground.ground if job.ground.name else t.ground
    return Scenario(t.path, t.duration_s if job.seconds is None else job.seconds, t.fps, motions,
                    ground, [character])


def _intervals(planted: NDArray[np.bool_], fps: float) -> list[list[float]]:
    """``[[t0_s, t1_s], ...]``: the times of the first and last frame of each run of True in
    ``planted`` (frames,) (the runs of :func:`ecs_anim.io.contacts.true_runs`)."""
    from ecs_anim.io.contacts import true_runs as runs

    return [[round(a / fps, 4), round(b / fps, 4)] for a, b in runs(planted)]


def foot_skate_ratio(positions: F64, ground: Ground, fps: float) -> float:
    """The fraction of all frames in which a foot's toe joint is under :data:`SKATE_HEIGHT_M`
    above the ground and moved horizontally more than :data:`SKATE_STEP_M` per 1/30 s since the
    frame before (the motion-synthesis literature's foot skate); ``positions`` (frames,
    joints, 3) world metres."""
    from ecs_anim.runtime.metrics import TOES

    toes = positions[:, TOES]  # (frames, 2, 3)
    toe_above = toes[..., 2] - ground.height(toes[..., :2])
    step = np.linalg.norm(np.diff(toes[..., :2], axis=0), axis=-1) * (fps / SKATE_REFERENCE_HZ)
    skating = (toe_above[1:] < SKATE_HEIGHT_M) & (step > SKATE_STEP_M)  # (frames - 1, 2)
    return float(np.count_nonzero(skating.any(axis=1)) / max(positions.shape[0], 1))


def run_job(job: Job, motion: NormalizedMotion) -> Outcome:
    """Play ``motion`` for ``job`` and return its record and files (nothing is written here).
    The simulation, metrics and encoders are those ``ecs-anim run --export`` uses."""
    from ecs_anim.io.export import bvh_from_rotations, write_npz
    from ecs_anim.runtime.metrics import MetricsRecorder
    from ecs_anim.scenario import build_simulation

    start = time.perf_counter()
    scenario = job_scenario(job, motion)
    ticks = round(scenario.duration_s * scenario.fps)
    if ticks < 1:
        raise EcsAnimError(f"--seconds {scenario.duration_s:g} is less than one tick at "
                           f"{scenario.fps:g} Hz")
    rotations = any(f in ("bvh", "glb") for f in job.formats)
    with build_simulation(scenario, rotations=rotations) as sim:
        recorder = MetricsRecorder(sim)
        n_joints = sim.store.positions.shape[1]
        positions = np.empty((ticks, n_joints, 3))
        planted = np.empty((ticks, 2), bool)
        local = None
        for tick in range(ticks):
            sim.step()
            recorder.record()
            positions[tick] = sim.store.positions[0]
            planted[tick] = sim.store.contact_weight[0] >= 1.0
            if rotations:
                if local is None:
                    local = np.empty((ticks,) + sim.store.local_rotations.shape[1:])
                local[tick] = sim.store.local_rotations[0]
        report = recorder.report()
        ground = sim.ground
    if not np.all(np.isfinite(positions)):
        raise EcsAnimError(f"{job.stem}: the simulation gave non-finite positions (bug); nothing "
                           "written")
    morph, fps = job.body.morphology, scenario.fps
    files: dict[str, bytes] = {}
    for ext in job.formats:
        name = f"{job.stem}.{ext}"
        if ext == "bvh":
            assert local is not None
            files[name] = bvh_from_rotations(morph, positions[:, 0], local, fps).encode("utf-8")
        elif ext == "npz":
            buffer = io.BytesIO()
            write_npz(buffer, positions, fps, planted)
            files[name] = buffer.getvalue()
        else:
            from ecs_anim.io.export.gltf import glb_bytes

            assert local is not None
            files[name] = glb_bytes(morph, positions[:, 0], local, fps)
    character = report["characters"][0]
    record = {
        "clip": job.clip, "body": job.body.name, "ground": job.ground.name,
        "stature_m": round(morph.stature, 4), "frames": ticks, "status": "ok", "error": "",
        "duration_s": round(ticks / fps, 6),
        "slide_max_mm": character["foot_sliding_mm_per_frame"]["max"],
        "slide_mean_mm": character["foot_sliding_mm_per_frame"]["mean"],
        "penetration_max_mm": character["ground_penetration_mm_max"],
        "floating_max_mm": character["floating_mm_max"],
        "bone_error_m": character["bone_length_error_m_max"],
        "com_error_mm": character["com_error_mm_max"],
        "foot_skate_ratio": round(foot_skate_ratio(positions, ground, fps), 4),
        "seconds": round(time.perf_counter() - start, 4),
        "outputs": list(files),
        "constraint_errors_mm": {k["name"]: k["error_mm_max_fully_active"]
                                 for k in report["constraints"]},
        "contacts": {"left": _intervals(planted[:, 0], fps), "right": _intervals(planted[:, 1], fps)},
    }
    return Outcome(record, files)


def import_task(path: str) -> tuple[NormalizedMotion | None, str]:
    """A worker's import: (motion, "") or (None, the one-line error)."""
    try:
        return import_clip(path), ""
    except Exception as exc:
        return None, error_text(exc)


def job_task(job: Job, imported: tuple[NormalizedMotion | None, str]) -> Outcome:
    """A worker's job, from what :func:`import_task` returned for its clip."""
    motion, error = imported
    if motion is None:
        return Outcome(failed_record(job, error))
    start = time.perf_counter()
    try:
        return run_job(job, motion)
    except Exception as exc:
        return Outcome(failed_record(job, error_text(exc), time.perf_counter() - start))


# --------------------------------------------------------------------------------------------
# Engines: each yields (job, outcome) as jobs finish, in any order.

WorkList = dict[str, list[Job]]  # clip path -> its jobs to run


def _in_process(work: WorkList) -> Iterator[tuple[Job, Outcome]]:
    """``--jobs 1``: everything in this process (no pool, nothing pickled)."""
    for clip, jobs in work.items():
        imported = import_task(clip)
        for job in jobs:
            yield job, job_task(job, imported)


#: Why a job failed whose worker process died under it (and again when it ran alone).
WORKER_DIED = "its worker process died (killed by a signal, or out of memory)"
_started: Any = None  # in a pool worker: the queue it tells which task it starts


def _set_started(queue: Any) -> None:
    """A pool worker's start: the queue it tells which task it starts; its kernels tick on one
    thread (the pool's processes share the cores, and a kernel thread spins between chunks)."""
    global _started
    _started = queue
    kernels.set_threads(1)


def _ray_job_task(job: Job, imported: tuple[NormalizedMotion | None, str]) -> Outcome:
    """:func:`job_task` in a Ray worker, which has one CPU: its kernels tick on one thread."""
    kernels.set_threads(1)
    return job_task(job, imported)


def _pool_task(key: str, function: Any, *args: Any) -> Any:
    """``function(*args)`` in a pool worker, saying first that task ``key`` started, so a worker
    that dies is matched with the task it ran."""
    _started.put(key)
    return function(*args)


def _local_pool(work: WorkList, workers: int) -> Iterator[tuple[Job, Outcome]]:
    """A process pool of ``workers``: each clip imported once (a task), then its jobs as tasks
    given the motion. A worker that dies (SIGKILL, out of memory) breaks the pool: a new pool
    takes the unfinished tasks, those that were running each run alone first; one that kills
    its worker again, alone, fails (for an import, its clip's jobs) and the others go on."""
    from concurrent.futures.process import BrokenProcessPool

    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    jobs = {job.stem: job for clip_jobs in work.values() for job in clip_jobs}
    imported: dict[str, Any] = {}
    todo: list[str] = [f"import:{clip}" for clip in work]  # task keys: import:<clip>, job:<stem>
    suspects: list[str] = []  # running when a pool broke: each runs alone next
    blind = 0  # pools that broke with no task running
    while todo or suspects:
        alone = suspects.pop(0) if suspects else None
        started = context.SimpleQueue()
        pool = ProcessPoolExecutor(max_workers=1 if alone else workers, mp_context=context,
                                   initializer=_set_started, initargs=(started,))
        tasks: dict[Future[Any], str] = {}
        began: list[str] = []  # keys the workers said they started, read as they come (a full
        broken = False         # pipe would block the workers)

        def read_started(started: Any = started, began: list[str] = began) -> None:
            try:
                while not started.empty():
                    began.append(started.get())
            except (OSError, EOFError, ValueError, pickle.UnpicklingError):
                pass  # a worker killed while it said so: what was read is what is known

        def submit(key: str, pool: ProcessPoolExecutor = pool,
                   tasks: dict[Future[Any], str] = tasks) -> None:
            nonlocal broken
            if broken:
                return
            name = key.split(":", 1)[1]
            try:
                if key.startswith("import:"):
                    future = pool.submit(_pool_task, key, import_task, name)
                else:
                    job = jobs[name]
                    future = pool.submit(_pool_task, key, job_task, job, imported[job.clip_path])
            except BrokenProcessPool:
                broken = True
                return
            tasks[future] = key

        try:
            for key in [alone] if alone else list(todo):
                submit(key)
            pending = set(tasks)
            while pending and not broken:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                read_started()
                for future in done:
                    key = tasks[future]
                    name = key.split(":", 1)[1]
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        broken = True
                        continue
                    except Exception as exc:
                        result = (None, error_text(exc)) if key.startswith("import:") else \
                            Outcome(failed_record(jobs[name], error_text(exc)))
                    if key in todo:
                        todo.remove(key)
                    if key.startswith("job:"):
                        yield jobs[name], result
                        continue
                    imported[name] = result
                    for job in work[name]:
                        if result[0] is None:
                            yield job, Outcome(failed_record(job, result[1]))
                            continue
                        todo.append(f"job:{job.stem}")
                        if alone is None:  # a task run alone runs with nothing else
                            submit(todo[-1])
                            if not broken:
                                pending.add(next(reversed(tasks)))
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        if not broken:
            continue
        if alone is not None:  # it killed its worker again, running alone: it fails
            name = alone.split(":", 1)[1]
            if alone.startswith("import:"):
                for job in work[name]:
                    yield job, Outcome(failed_record(job, f"{name}: the import's {WORKER_DIED}"))
            else:
                yield jobs[name], Outcome(failed_record(jobs[name], WORKER_DIED))
            continue
        read_started()
        running = [key for key in dict.fromkeys(began) if key in todo]
        if not running:  # a worker died before its task began: the pool itself cannot work
            blind += 1
            if blind >= 3:
                for key in todo:
                    name = key.split(":", 1)[1]
                    for job in work[name] if key.startswith("import:") else [jobs[name]]:
                        yield job, Outcome(failed_record(job, f"{WORKER_DIED} before its task began"))
                return
        for key in running:
            todo.remove(key)
        suspects += running


#: How long ``--address HOST:PORT`` may take to accept a TCP connection before it is unreachable.
RAY_CONNECT_TIMEOUT_S = 3.0


def check_ray_address(address: str | None) -> None:
    """Refuse, in one line and quickly, what ``ray.init`` would wait minutes on: Ray is not
    installed, ``ray://`` (Ray Client: the clips are imported on the driver's node, which with
    Ray Client is the head, not this machine), or a ``HOST:PORT`` that does not accept a TCP
    connection within :data:`RAY_CONNECT_TIMEOUT_S`. ``auto`` is left to Ray."""
    import importlib.util
    import socket

    if importlib.util.find_spec("ray") is None:
        raise EcsAnimError("--engine ray needs Ray: pip install 'ecs_anim[ray]'")
    if not address or address == "auto":
        return
    if "://" in address:
        raise EcsAnimError(f"--address {address}: Ray Client (ray://) is not supported; run the "
                           "command on a cluster node (--address auto) or give the head's "
                           "HOST:PORT (e.g. head:6379) from a machine in the cluster")
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise EcsAnimError(f"--address {address}: expected HOST:PORT (e.g. head:6379) or auto")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise EcsAnimError(f"--address {address}: no Ray cluster reachable there ({reason} "
                           f"within {RAY_CONNECT_TIMEOUT_S:g} s)") from None


def _ray_engine(work: WorkList, workers: int, address: str | None) -> Iterator[tuple[Job, Outcome]]:
    """The jobs as Ray tasks on the cluster at ``address``, or on a local one of ``workers``
    CPUs started here (a Ray already initialized in this process is used as it is). Clips are
    imported on this machine's node (where the files are), once each; jobs run anywhere and
    return their bytes, which this process writes."""
    try:
        import ray
    except ImportError:
        raise EcsAnimError("--engine ray needs Ray: pip install 'ecs_anim[ray]'") from None
    started = not ray.is_initialized()
    if started:
        try:
            if address:
                ray.init(address=address, logging_level=logging.WARNING, log_to_driver=False)
            else:
                ray.init(num_cpus=workers, include_dashboard=False, logging_level=logging.WARNING,
                         log_to_driver=False)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"at {address}" if address else "locally"
            raise EcsAnimError(f"--engine ray: cannot start or reach a Ray cluster {where}: "
                               f"{' '.join(str(exc).split())[:200]}") from None
    try:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
        import_remote = ray.remote(import_task).options(num_cpus=1, scheduling_strategy=here)
        job_remote = ray.remote(_ray_job_task).options(num_cpus=1)
        refs: dict[Any, Job] = {}
        for clip, jobs in work.items():
            imported = import_remote.remote(clip)  # one object, shared by the clip's jobs
            for job in jobs:
                refs[job_remote.remote(job, imported)] = job
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                job = refs.pop(ref)
                try:
                    yield job, ray.get(ref)
                except Exception as exc:
                    yield job, Outcome(failed_record(job, f"ray task failed: "
                                                          f"{' '.join(str(exc).split())[:200]}"))
    finally:
        if started:
            ray.shutdown()


# --------------------------------------------------------------------------------------------
# The driver: check, skip what is done, run, write.


class Progress:
    """Jobs done, failures and time left: a tqdm bar on a terminal, else one plain line a job
    (``[3/12] walk/child_bumps ok 0.41 s; 0 failed; about 4 s left``) on stderr."""

    def __init__(self, total: int, stream: Any = None):
        self.total, self.done, self.failed = total, 0, 0
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.bar = None
        if total and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="job", file=self.stream, dynamic_ncols=True)

    def update(self, stem: str, record: dict[str, Any]) -> None:
        self.done += 1
        self.failed += record["status"] == "failed"
        if record["status"] == "failed":
            self.write(f"error: {stem}: {record['error']}")
        if self.bar is not None:
            self.bar.set_postfix(failed=self.failed, refresh=False)
            self.bar.update(1)
            return
        elapsed = time.perf_counter() - self.start
        left = elapsed / self.done * (self.total - self.done)
        self.write(f"[{self.done}/{self.total}] {stem} {record['status']} {record['seconds']:.2f} s; "
                   f"{self.failed} failed; about {left:.0f} s left")

    def write(self, line: str) -> None:
        if self.bar is not None:
            self.bar.write(line, file=self.stream)
        else:
            print(line, file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _check_folder(out: Path) -> None:
    """Refuse a batch folder that cannot be written or holds files no batch wrote."""
    from ecs_anim.core.files import folder_problem

    problem = folder_problem(out)
    if problem is not None:
        raise EcsAnimError(f"--out {problem}")
    if out.is_dir() and not (out / BATCH_MARKER).is_file() and any(out.iterdir()):
        raise EcsAnimError(f"--out {out}: holds files ecs-anim batch did not write (no "
                           f"{BATCH_MARKER}); give a new or empty folder")


def _check_outputs(plan: Plan, jobs: list[Job]) -> None:
    """Refuse outputs (every format a job may write or delete, its stamp, the metrics and the
    report) that are one of the batch's inputs (by real path or, hard links, by inode)."""
    from ecs_anim.core.files import input_problem

    names = [rel for job in jobs for rel in (*job.all_outputs(), job.stamp)] + list(RESERVED)
    for rel in names:
        problem = input_problem(plan.out / rel, plan.inputs)
        if problem is not None:
            raise EcsAnimError(f"--out {problem.replace(' command', ' batch')}")


def _done_record(out: Path, job: Job, digest: str) -> dict[str, Any] | None:
    """The record of an earlier run of ``job`` whose stamp has ``digest`` and whose outputs all
    exist, or None."""
    try:
        stamp = json.loads((out / job.stamp).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(stamp, dict) or stamp.get("digest") != digest:
        return None
    record = stamp.get("record")
    if not isinstance(record, dict) or record.get("outputs") != job.outputs():
        return None
    if not all((out / rel).is_file() for rel in job.outputs()):
        return None
    return record


def _clear(out: Path, job: Job) -> None:
    """Delete a job's stamp, then its files in every format (a failed job leaves none, a job
    redone with other formats none of the others)."""
    try:
        (out / job.stamp).unlink(missing_ok=True)
        for rel in job.all_outputs():
            (out / rel).unlink(missing_ok=True)
    except OSError as exc:
        raise EcsAnimError(f"{out / job.stem}: cannot delete an earlier run's files "
                           f"({exc.strerror or exc})") from None


def _commit(out: Path, job: Job, outcome: Outcome, digest: str) -> None:
    """Write a finished job whole or not at all: every file goes to a temporary name first
    (:func:`~ecs_anim.core.files.atomic_output`, all open at once); then the stamp and the earlier
    run's files in every format are deleted, the new files renamed in, and the new stamp
    written last. A job counts as done only with its stamp, so a kill at any point leaves it to
    be redone, never with old and new files mixed."""
    from contextlib import ExitStack

    from ecs_anim.core.files import atomic_output

    if outcome.record["status"] != "ok":
        _clear(out, job)
        return
    with ExitStack() as files:
        for rel, data in outcome.files.items():
            # the batch's own file (checked against the inputs by _check_outputs)
            files.enter_context(atomic_output(out / rel, force=True)).write(data)
        _clear(out, job)
    # leaving the block renamed every file in (or, when one failed, removed every temporary)
    with atomic_output(out / job.stamp, force=True) as f:
        f.write(json.dumps({"digest": digest, "record": outcome.record}, allow_nan=False,
                           indent=1).encode("utf-8"))


def json_safe(value: Any) -> Any:
    from ecs_anim.apps.cli.args import json_safe as safe

    return safe(value)


def write_metrics(out: Path, records: list[dict[str, Any]], seconds: float) -> None:
    """``metrics.json`` ({"jobs", "version", "seconds"}) and ``metrics.csv`` (the scalar fields,
    then one ``constraint:<name>_mm`` column per constraint name, in first-seen order)."""
    from ecs_anim.core.files import atomic_output

    body = {"jobs": records, "version": project_version(), "seconds": round(seconds, 3)}
    with atomic_output(out / "metrics.json", force=True) as f:
        f.write(json.dumps(json_safe(body), indent=1, allow_nan=False).encode("utf-8"))
    names: list[str] = []
    for record in records:
        names += [n for n in record["constraint_errors_mm"] if n not in names]
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow([*CSV_FIELDS, *(f"constraint:{n}_mm" for n in names)])
    for record in records:
        values = [record[k] for k in CSV_FIELDS] + [record["constraint_errors_mm"].get(n) for n in names]
        writer.writerow(["" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v
                         for v in values])
    with atomic_output(out / "metrics.csv", force=True) as f:
        f.write(text.getvalue().encode("utf-8"))




def run_batch(plan: Plan, engine: str = "local", workers: int | None = None,
              address: str | None = None, force: bool = False,
              stream: Any = None) -> list[dict[str, Any]]:
    """Run a plan: skip jobs done with the same inputs (unless ``force``), run the rest on
    ``engine`` (``local`` or ``ray``) with ``workers`` processes (default: every core), write
    each job's files, then the metrics and the report. Returns the records in plan order."""
    from ecs_anim.core.files import atomic_output

    start = time.perf_counter()
    jobs = plan.jobs()
    _check_folder(plan.out)
    _check_outputs(plan, jobs)
    if engine == "ray":
        check_ray_address(address)
    version = f"{project_version()}+{source_digest()}"
    clip_digests = {str(c): hashlib.sha256(c.read_bytes()).hexdigest() for c in plan.clips}
    digests = {job.stem: job_digest(job, clip_digests[job.clip_path], version) for job in jobs}
    records: dict[str, dict[str, Any]] = {}
    work: WorkList = {}
    for job in jobs:
        earlier = None if force else _done_record(plan.out, job, digests[job.stem])
        if earlier is not None:
            records[job.stem] = earlier | {"status": "skipped"}
        else:
            work.setdefault(job.clip_path, []).append(job)
    if not (plan.out / BATCH_MARKER).is_file():
        with atomic_output(plan.out / BATCH_MARKER, force=True) as f:
            f.write(json.dumps({"written_by": "ecs-anim batch",
                                "version": project_version()}).encode("utf-8"))
    n_work = sum(len(j) for j in work.values())
    workers = max(1, min(workers or os.cpu_count() or 1, max(n_work, 1)))
    progress = Progress(n_work, stream)
    if len(records):
        progress.write(f"{len(records)} of {len(jobs)} job(s) already done with the same inputs: "
                       "skipped (--force redoes them)")
    try:
        if engine == "ray":
            outcomes = _ray_engine(work, workers, address)
        elif workers == 1:
            outcomes = _in_process(work)
        else:
            outcomes = _local_pool(work, workers)
        for job, outcome in outcomes:
            if outcome.record["status"] == "ok":
                try:
                    _commit(plan.out, job, outcome, digests[job.stem])
                except EcsAnimError as exc:  # e.g. the disk is full: this job failed
                    outcome = Outcome(failed_record(job, str(exc), outcome.record["seconds"]))
                    _clear(plan.out, job)
            else:
                _clear(plan.out, job)
            records[job.stem] = outcome.record
            progress.update(job.stem, outcome.record)
    finally:
        progress.close()
    ordered = [records[job.stem] for job in jobs]
    write_metrics(plan.out, ordered, time.perf_counter() - start)
    from ecs_anim.apps.batch.report import write_report

    write_report(plan.out / "report.html", ordered)
    return ordered


def cmd_batch(args: argparse.Namespace) -> int:
    """``ecs-anim batch``: 0 when every job is ok (or skipped), 1 when any failed."""
    if args.address and args.engine != "ray":
        raise EcsAnimError("--address is for --engine ray")
    plan = plan_from_args(args)
    start = time.perf_counter()
    records = run_batch(plan, args.engine, args.jobs, args.address, args.force)
    counts = {s: sum(r["status"] == s for r in records) for s in ("ok", "skipped", "failed")}
    print(f"{len(records)} job(s) in {time.perf_counter() - start:.1f} s: {counts['ok']} ok, "
          f"{counts['skipped']} skipped, {counts['failed']} failed; wrote {plan.out}/metrics.csv, "
          "metrics.json, report.html")
    if counts["failed"]:
        print(f"{counts['failed']} of {len(records)} job(s) failed; the others were written",
              file=sys.stderr)
        return 1
    return 0


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``batch`` to the CLI's subparsers; returns its parser (``func`` is :func:`cmd_batch`)."""
    from ecs_anim.apps.cli.args import positive_float, positive_int

    p = subparsers.add_parser(
        "batch", help="play many clips on many bodies over many grounds; metrics and a report",
        description="Every clip x body x ground as a job, in parallel; outputs "
                    "DIR/<clip>/<body>[_<ground>].{bvh,npz,glb}, DIR/metrics.csv, metrics.json "
                    "and report.html. A second run skips jobs done with the same inputs.")
    p.add_argument("clips", nargs="*", metavar="CLIP",
                   help="clips: .bvh, .c3d or .nmo files, globs ('mocap/*.bvh') or folders")
    p.add_argument("--manifest", metavar="FILE.yaml",
                   help="clips, bodies, grounds, template, formats, out from a YAML file")
    p.add_argument("--bodies", metavar="B,B,...",
                   help=f"comma-separated: presets ({', '.join(PRESET_SPECS)}), morphology "
                        "FILE.yaml, or stature_<m> (e.g. stature_1.35)")
    p.add_argument("--grounds", metavar="FILE.yaml",
                   help="grounds: {name: {type: ...}} in the scenario ground syntax (default: "
                        "the plane z = 0, no suffix)")
    p.add_argument("--template", metavar="SCENARIO.yaml",
                   help="a scenario with one character: its fps, duration, ground, placement, "
                        "constraints and COM settings for every job")
    p.add_argument("--out", metavar="DIR", help="the batch folder")
    p.add_argument("--formats", metavar="F,F", help="of bvh, npz, glb (default bvh,npz)")
    p.add_argument("--seconds", type=positive_float, metavar="S",
                   help="simulate S seconds per job instead of the clip's length")
    p.add_argument("--engine", choices=["local", "ray"], default="local",
                   help="local: a process pool on this machine (default); ray: Ray tasks")
    p.add_argument("--jobs", type=positive_int, metavar="N",
                   help="worker processes (default: every core; 1: in this process); with "
                        "--engine ray, the CPUs of the local Ray it starts")
    p.add_argument("--address", metavar="HOST:PORT",
                   help="--engine ray: a running Ray cluster's head (HOST:PORT, e.g. head:6379, "
                        "or auto on a cluster node); default: start a local one")
    p.add_argument("--force", action="store_true", help="redo jobs already done")
    p.set_defaults(func=cmd_batch)
    assert isinstance(p, argparse.ArgumentParser)
    return p


__all__ = ["add_parser", "cmd_batch", "load_manifest", "plan_from_args", "run_batch", "run_job"]
