"""What a batch runs and where its files go: bodies, grounds, a template, the jobs
(clip x body x ground) and the checked plan that holds them.

A job writes ``DIR/<clip>/<body>[_<ground>].<format>`` and, beside those, a hidden stamp
(:data:`STAMP_SUFFIX`); the batch's own files (:data:`RESERVED`) and its marker
(:data:`BATCH_MARKER`) sit in ``DIR``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.ground import Ground, Plane
from ecs_anim.core.morphology import Morphology
from ecs_anim.motion.clip import NormalizedMotion

#: Output formats a batch writes (``--formats``).
FORMATS = ("bvh", "npz", "glb")
DEFAULT_FORMATS = ("bvh", "npz")
#: Written first into a batch folder: a folder without it that holds anything is not ours.
BATCH_MARKER = ".ecs-anim-batch.json"
#: The batch's own files in its folder: no clip may be named so (its folder would be theirs).
RESERVED = ("metrics.csv", "metrics.json", "report.html")
#: Beside each job's outputs, written after them: the job's input hash and its record.
STAMP_SUFFIX = ".ecs-anim-job.json"
#: The whole product is bounded so a typo cannot plan a year of work.
MAX_JOBS = 1_000_000


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
class OntoRig:
    """The user's rig every job is written onto (``--onto RIG``, ``onto:``): its file, its
    joint map (``--map``: a preset, a map YAML or None to detect) and a hash of both files'
    bytes and the map (part of every job's hash)."""

    path: str
    map_spec: str | None
    digest: str


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
    onto: OntoRig | None = None  # the files retargeted onto this rig

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
    onto: OntoRig | None = None

    def jobs(self) -> list[Job]:
        return [Job(str(c), c.stem, b, g, self.formats, self.seconds, self.template, self.onto)
                for c in self.clips for b in self.bodies for g in self.grounds]


def make_plan(clips: list[Path], bodies: list[Body], out: Path,
              grounds: list[NamedGround] | None = None,
              formats: tuple[str, ...] = DEFAULT_FORMATS, template: Template | None = None,
              seconds: float | None = None, inputs: Sequence[str] = (),
              onto: OntoRig | None = None) -> Plan:
    """A checked plan. ``grounds`` default to the template's ground, or else the plane z = 0
    (no suffix on the files); ``inputs`` are the files read besides the clips and the template
    (the plan adds those); ``onto``: the rig every job is written onto. Refuses ``seconds`` out of bounds (:func:`_check_seconds`), two
    body-ground pairs that would write the same files, and more than :data:`MAX_JOBS` jobs."""
    if seconds is not None:
        _check_seconds(seconds, clips, template)
    grounds = grounds or [NamedGround("", template.ground if template else Plane())]
    stems: dict[str, str] = {}
    for b in bodies:
        for g in grounds:
            stem = b.name + (f"_{g.name}" if g.name else "")
            if stem in stems:
                raise EcsAnimError(f"body {b.name!r} over ground {g.name!r} and {stems[stem]} "
                                   f"both write {stem}.*; rename one")
            stems[stem] = f"body {b.name!r} over ground {g.name!r}"
    read = [*inputs, *(str(c) for c in clips)]
    if template is not None:
        read += [template.path, *template.input_files]
    plan = Plan(clips, bodies, grounds, formats, out, template, seconds, read, onto)
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
