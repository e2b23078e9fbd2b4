"""``ecs-anim batch``: many clips played on many bodies over many grounds, in parallel.

A batch is the product clips x bodies x grounds. Each job plays one clip on one body over one
ground through the same pipeline as ``ecs-anim run`` (:func:`~ecs_anim.scenario.build_simulation`
on an in-memory :class:`~ecs_anim.scenario.Scenario`, metrics by
:class:`~ecs_anim.metrics.MetricsRecorder`), and writes ``DIR/<clip>/<body>[_<ground>].<format>``.

Who does what:

* the driver (this process) plans the jobs, skips those already done (a stamp beside the
  outputs holds a content hash of clip, body, ground, template, formats and project version),
  and writes every file, each atomically (:func:`~ecs_anim.files.atomic_output`), the stamp
  last: a job killed half-way has no stamp and is done again, so its outputs end whole;
* the workers (a local process pool, or Ray tasks) import each clip once and run jobs; they
  return the files' bytes, so workers on other machines need no shared file system, and the
  local and Ray engines produce the same bytes from the same function.

Finally ``DIR/metrics.json``, ``DIR/metrics.csv`` (one row per job, the scalar fields of
:data:`CSV_FIELDS` then one ``constraint:<name>_mm`` column per stored constraint) and
``DIR/report.html`` (:func:`ecs_anim.batch_report.write_report`).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import difflib
import glob
import hashlib
import io
import json
import logging
import math
import multiprocessing
import os
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

from .errors import EcsAnimError, InputError, quoted
from .ground import Ground, Plane
from .morphology import PRESET_SPECS, Morphology, load_morphology_yaml
from .motion import NormalizedMotion

F64 = NDArray[np.float64]

#: Output formats a batch writes (``--formats``); glb needs :mod:`ecs_anim.gltf`.
FORMATS = ("bvh", "npz", "glb")
DEFAULT_FORMATS = ("bvh", "npz")
#: Clip files a batch reads, and what a folder given as a clip contributes.
CLIP_SUFFIXES = (".bvh", ".c3d", ".nmo")
#: Written first into a batch folder: a folder without it that holds anything is not ours.
BATCH_MARKER = ".ecs-anim-batch.json"
#: Beside each job's outputs, written after them: the job's input hash and its record.
STAMP_SUFFIX = ".ecs-anim-job.json"
#: Names of bodies and grounds (they name files): as scenario names, without path separators.
_NAME = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*")
MAX_NAME_LENGTH = 64
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
    """The installed ecs_anim version: part of every job's hash, so an upgrade redoes jobs."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ecs_anim")
    except PackageNotFoundError:
        return "0+unknown"


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
    if not _NAME.fullmatch(name):
        return f"{quoted(name)}: a {what} name names files: letters, digits, _ . - (not starting with .)"
    if len(name) > MAX_NAME_LENGTH:
        return f"a {what} name has at most {MAX_NAME_LENGTH} characters, got {len(name)}"
    return None


def stature_name(stature_m: float, sex: str = "male", proportions: str = "adult") -> str:
    """``stature_1.35`` (``_female``, ``_child`` appended when not the default)."""
    return f"stature_{stature_m:.2f}" + ("" if sex == "male" else f"_{sex}") + \
        ("" if proportions == "adult" else f"_{proportions}")


def body_from_text(text: str, base: Path = Path(".")) -> Body:
    """A body given as text: a preset, a morphology YAML file (named by its stem; relative
    paths from ``base``) or ``stature_<metres>`` (adult proportions)."""
    if text in PRESET_SPECS:
        return Body(text, Morphology.preset(text))
    if text.lower().endswith((".yaml", ".yml")):
        path = Path(text) if Path(text).is_absolute() else base / text
        if not path.is_file():
            raise InputError(path, "no such morphology file")
        problem = _check_name(path.stem, "body")
        if problem:
            raise InputError(path, problem)
        return Body(path.stem, load_morphology_yaml(path))
    match = re.fullmatch(r"stature_([0-9]+(?:\.[0-9]+)?)", text)
    if match:
        stature = float(match[1])
        if not 0.3 <= stature <= 3.0:
            raise EcsAnimError(f"body {text}: a stature from 0.3 to 3.0 m")
        name = stature_name(stature)
        return Body(name, Morphology.from_stature(stature, name=name))
    close = difflib.get_close_matches(text, list(PRESET_SPECS), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise EcsAnimError(f"body {quoted(text)}: not a preset{hint}, a .yaml morphology or "
                       f"stature_<m>; presets: {', '.join(PRESET_SPECS)}")


def _reader(path: str | Path) -> Any:
    from .scenario import _Reader

    return _Reader(str(path))


def _manifest_body(r: Any, node: yaml.Node, where: str, base: Path) -> list[Body]:
    """One ``bodies:`` item: a name (see :func:`body_from_text`) or
    ``{statures: {from_m, to_m, count}, proportions: adult|child, sex: male|female}``."""
    if isinstance(node, yaml.ScalarNode):
        text = r.string(node, where)
        try:
            return [body_from_text(text, base)]
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
            for n, s in zip(names, statures)]


def _grounds_mapping(r: Any, node: yaml.Node, where: str) -> list[NamedGround]:
    """``grounds: {name: ground, ...}`` in the scenario ground syntax (docs/scenarios.md)."""
    from .scenario import _ground

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
        grounds.append(NamedGround(name, _ground(r, value, f"{where}.{name}")))
    return grounds


def load_grounds(path: str | Path) -> list[NamedGround]:
    """A grounds file (``--grounds``): ``grounds: {name: ground, ...}``."""
    from .scenario import _compose

    r = _reader(path)
    root = _compose(Path(path), "grounds", "the grounds file")
    top = r.mapping(root, "", {"grounds": True})
    return _grounds_mapping(r, top["grounds"], "grounds")


def load_template(path: str | Path) -> Template:
    """A scenario with exactly one character: every job takes its fps, duration, ground (when
    the batch names none), queued motions, placement, constraints and COM settings; the clip
    and the body replace the character's motion and morphology."""
    from .scenario import load_scenario

    scenario = load_scenario(path)
    if len(scenario.characters) != 1:
        raise InputError(path, f"a batch template has exactly one character, found "
                               f"{len(scenario.characters)}")
    character = scenario.characters[0]
    if any(k.target_character not in (None, character.name) for k in character.constraints):
        raise InputError(path, "a batch template's constraints aim at the world or its own body")
    return Template(str(path), scenario.fps, scenario.duration_s, scenario.ground,
                    dict(scenario.motions), character, _files_digest(scenario.input_files))


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
    out, seconds (absent keys absent)."""
    from .scenario import _compose

    path = Path(path)
    base = path.parent
    r = _reader(path)
    root = _compose(path, "batch manifest", "the manifest")
    top = r.mapping(root, "", MANIFEST_KEYS)
    parts: dict[str, Any] = {}
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
        for body in _manifest_body(r, node, f"bodies[{i}]", base):
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
        inputs.append(args.manifest)
    else:
        parts = {"clips": expand_clips(args.clips or [])}
        if not args.bodies:
            raise EcsAnimError("batch: give --bodies (e.g. child,adult_male,tall) or --manifest")
        bodies: list[Body] = []
        for text in (t.strip() for t in args.bodies.split(",")):
            if not text:
                continue
            body = body_from_text(text)
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
        inputs.append(template.path)
    plan = Plan(parts["clips"], bodies, grounds, parts.get("formats", DEFAULT_FORMATS),
                parts["out"], template, parts.get("seconds"), inputs)
    n_jobs = len(plan.clips) * len(bodies) * len(grounds)
    if n_jobs > MAX_JOBS:
        raise EcsAnimError(f"batch: {n_jobs:,} jobs; at most {MAX_JOBS:,} in one batch")
    return plan


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
    and the project version. Equal hashes mean equal outputs."""
    data = {"version": version, "clip": clip_digest, "body": _canonical(job.body),
            "ground": _canonical(job.ground), "formats": list(job.formats),
            "seconds": _canonical(job.seconds),
            "template": None if job.template is None else job.template.digest}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------------
# Work done by the workers: import a clip, run a job. Pure functions of their inputs.


def import_clip(path: str | Path) -> NormalizedMotion:
    """The motion in a clip file, read as a scenario's ``motions:`` reads it (the importers'
    defaults), so a job plays what ``ecs-anim run`` would."""
    from .c3d_import import import_c3d
    from .importing import import_bvh
    from .motion import load_nmo

    suffix = Path(path).suffix.lower()
    if suffix == ".nmo":
        return load_nmo(path)
    if suffix == ".c3d":
        return import_c3d(path)
    return import_bvh(path)


@dataclass
class Outcome:
    """A finished job: its record (see :func:`job_record`) and its files' bytes by path
    relative to the batch folder (empty when it failed)."""

    record: dict[str, Any]
    files: dict[str, bytes] = field(default_factory=dict)


def error_text(exc: BaseException) -> str:
    """A job's one-line error: the user error as the CLI prints it, or, for a bug, its type."""
    from .cli import error_line

    if isinstance(exc, (EcsAnimError, OSError)):
        return error_line(exc)
    return error_line(RuntimeError(f"internal error: {type(exc).__name__}: {exc}"))


def failed_record(job: Job, error: str, seconds: float = 0.0) -> dict[str, Any]:
    """The record of a job that failed with the one-line ``error``."""
    return {"clip": job.clip, "body": job.body.name, "ground": job.ground.name,
            "stature_m": round(job.body.morphology.stature, 4), "frames": 0, "status": "failed",
            "error": error, "slide_max_mm": None, "slide_mean_mm": None, "penetration_max_mm": None,
            "floating_max_mm": None, "bone_error_m": None, "com_error_mm": None,
            "foot_skate_ratio": None, "seconds": round(seconds, 4), "outputs": [],
            "constraint_errors_mm": {}, "contacts": {"left": [], "right": []}}


def job_scenario(job: Job, motion: NormalizedMotion) -> Any:
    """The in-memory scenario of a job: the clip (motion name = the clip's name) on the body at
    the origin, facing +x, not looping, at the clip's rate for its length; or, with a template,
    the template's character, rate and length with the clip and body swapped in."""
    from .components import MotionPlayer, Placement
    from .scenario import CharacterSpec, Scenario

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
    ``planted`` (frames,)."""
    edges = np.diff(np.concatenate([[0], planted.astype(np.int8), [0]]))
    starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    return [[round(a / fps, 4), round(b / fps, 4)] for a, b in zip(starts, stops)]


def foot_skate_ratio(positions: F64, ground: Ground, fps: float) -> float:
    """The fraction of all frames in which a foot's toe joint is under :data:`SKATE_HEIGHT_M`
    above the ground and moved horizontally more than :data:`SKATE_STEP_M` per 1/30 s since the
    frame before (the motion-synthesis literature's foot skate); ``positions`` (frames,
    joints, 3) world metres."""
    from .metrics import TOES

    toes = positions[:, TOES]  # (frames, 2, 3)
    toe_above = toes[..., 2] - ground.height(toes[..., :2])
    step = np.linalg.norm(np.diff(toes[..., :2], axis=0), axis=-1) * (fps / SKATE_REFERENCE_HZ)
    skating = (toe_above[1:] < SKATE_HEIGHT_M) & (step > SKATE_STEP_M)  # (frames - 1, 2)
    return float(np.count_nonzero(skating.any(axis=1)) / max(positions.shape[0], 1))


def run_job(job: Job, motion: NormalizedMotion) -> Outcome:
    """Play ``motion`` for ``job`` and return its record and files (nothing is written here).
    The simulation, metrics and encoders are those ``ecs-anim run --export`` uses."""
    from .exporting import bvh_from_rotations, write_npz
    from .metrics import MetricsRecorder
    from .scenario import build_simulation

    start = time.perf_counter()
    scenario = job_scenario(job, motion)
    ticks = max(1, round(scenario.duration_s * scenario.fps))
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
            from .gltf import glb_bytes

            assert local is not None
            files[name] = glb_bytes(morph, positions[:, 0], local, fps)
    character = report["characters"][0]
    record = {
        "clip": job.clip, "body": job.body.name, "ground": job.ground.name,
        "stature_m": round(morph.stature, 4), "frames": ticks, "status": "ok", "error": "",
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
    except Exception as exc:  # noqa: BLE001 - a bad clip fails its own jobs, never the batch
        return None, error_text(exc)


def job_task(job: Job, imported: tuple[NormalizedMotion | None, str]) -> Outcome:
    """A worker's job, from what :func:`import_task` returned for its clip."""
    motion, error = imported
    if motion is None:
        return Outcome(failed_record(job, error))
    start = time.perf_counter()
    try:
        return run_job(job, motion)
    except Exception as exc:  # noqa: BLE001 - one bad job must not stop the others
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


def _local_pool(work: WorkList, workers: int) -> Iterator[tuple[Job, Outcome]]:
    """A process pool of ``workers``: each clip imported once (a task), then its jobs as tasks
    given the motion."""
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context)
    try:
        imports: dict[Future[Any], str] = {pool.submit(import_task, clip): clip for clip in work}
        running: dict[Future[Any], Job] = {}
        pending: set[Future[Any]] = set(imports)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                if future in imports:
                    imported = _result(future, "the import's worker process died")
                    for job in work[imports.pop(future)]:
                        if imported[0] is None:
                            yield job, Outcome(failed_record(job, imported[1]))
                        else:
                            submitted = pool.submit(job_task, job, imported)
                            running[submitted] = job
                            pending.add(submitted)
                else:
                    job = running.pop(future)
                    try:
                        yield job, future.result()
                    except Exception as exc:  # noqa: BLE001 - the worker died (killed, out of memory)
                        yield job, Outcome(failed_record(job, f"worker failed: {error_text(exc)}"))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _result(future: Future[Any], message: str) -> Any:
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 - a dead worker fails the clip, not the batch
        return None, f"{message}: {error_text(exc)}"


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
        job_remote = ray.remote(job_task).options(num_cpus=1)
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
                except Exception as exc:  # noqa: BLE001 - a worker or node died
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
            from tqdm import tqdm  # type: ignore[import-untyped]

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
    from .files import folder_problem

    problem = folder_problem(out)
    if problem is not None:
        raise EcsAnimError(f"--out {problem}")
    if out.is_dir() and not (out / BATCH_MARKER).is_file() and any(out.iterdir()):
        raise EcsAnimError(f"--out {out}: holds files ecs-anim batch did not write (no "
                           f"{BATCH_MARKER}); give a new or empty folder")


def _check_outputs(plan: Plan, jobs: list[Job]) -> None:
    """Refuse outputs that would overwrite one of the batch's inputs (by real path)."""
    inputs = {os.path.realpath(p) for p in plan.inputs}
    for job in jobs:
        for rel in (*job.outputs(), job.stamp):
            if os.path.realpath(plan.out / rel) in inputs:
                raise EcsAnimError(f"--out {plan.out}: {rel} would overwrite an input of this "
                                   "batch; give another folder")
    for name in ("metrics.csv", "metrics.json", "report.html"):
        if os.path.realpath(plan.out / name) in inputs:
            raise EcsAnimError(f"--out {plan.out}: {name} would overwrite an input of this batch")


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


def _commit(out: Path, job: Job, outcome: Outcome, digest: str) -> None:
    """Write a finished job: its stamp goes first (a job being redone is not done), then each
    file atomically, then the new stamp, so a job counts as done only with all of its files."""
    from .files import atomic_output

    stamp = out / job.stamp
    stamp.unlink(missing_ok=True)
    if outcome.record["status"] != "ok":
        return
    for rel, data in outcome.files.items():
        with atomic_output(out / rel, force=True) as f:  # the batch's own file (checked above)
            f.write(data)
    with atomic_output(stamp, force=True) as f:
        f.write(json.dumps({"digest": digest, "record": outcome.record}, allow_nan=False,
                           indent=1).encode("utf-8"))


def _json_safe(value: Any) -> Any:
    from .cli import _json_safe as safe

    return safe(value)


def write_metrics(out: Path, records: list[dict[str, Any]], seconds: float) -> None:
    """``metrics.json`` ({"jobs", "version", "seconds"}) and ``metrics.csv`` (the scalar fields,
    then one ``constraint:<name>_mm`` column per constraint name, in first-seen order)."""
    from .files import atomic_output

    body = {"jobs": records, "version": project_version(), "seconds": round(seconds, 3)}
    with atomic_output(out / "metrics.json", force=True) as f:
        f.write(json.dumps(_json_safe(body), indent=1, allow_nan=False).encode("utf-8"))
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


def _write_report(out: Path, records: list[dict[str, Any]], progress: Progress) -> bool:
    """report.html by :func:`ecs_anim.batch_report.write_report`; False (said) if unavailable."""
    try:
        from .batch_report import write_report
    except ImportError as exc:
        progress.write(f"warning: no report.html ({exc})")
        return False
    write_report(out / "report.html", records)
    return True


def run_batch(plan: Plan, engine: str = "local", workers: int | None = None,
              address: str | None = None, force: bool = False,
              stream: Any = None) -> list[dict[str, Any]]:
    """Run a plan: skip jobs done with the same inputs (unless ``force``), run the rest on
    ``engine`` (``local`` or ``ray``) with ``workers`` processes (default: every core), write
    each job's files, then the metrics and the report. Returns the records in plan order."""
    from .files import atomic_output

    start = time.perf_counter()
    jobs = plan.jobs()
    _check_folder(plan.out)
    _check_outputs(plan, jobs)
    if "glb" in plan.formats:
        try:
            import ecs_anim.gltf  # noqa: F401
        except ImportError as exc:
            raise EcsAnimError(f"--formats glb: this install cannot write glTF ({exc})") from None
    version = project_version()
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
            f.write(json.dumps({"written_by": "ecs-anim batch", "version": version}).encode("utf-8"))
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
            else:
                (plan.out / job.stamp).unlink(missing_ok=True)
            records[job.stem] = outcome.record
            progress.update(job.stem, outcome.record)
    finally:
        progress.close()
    ordered = [records[job.stem] for job in jobs]
    write_metrics(plan.out, ordered, time.perf_counter() - start)
    _write_report(plan.out, ordered, progress)
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
    from .cli import positive_float, positive_int

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
                   help="--engine ray: a running Ray cluster (e.g. auto or ray://head:10001); "
                        "default: start a local one")
    p.add_argument("--force", action="store_true", help="redo jobs already done")
    p.set_defaults(func=cmd_batch)
    assert isinstance(p, argparse.ArgumentParser)
    return p


__all__ = ["add_parser", "cmd_batch", "load_manifest", "plan_from_args", "run_batch", "run_job"]
