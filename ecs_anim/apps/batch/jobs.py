"""Running one job, as a worker does: import a clip, play it for a job through the pipeline
of ``ecs-anim run`` (:func:`~ecs_anim.scenario.loader.build_simulation` on an in-memory
:class:`~ecs_anim.scenario.loader.Scenario`, metrics by
:class:`~ecs_anim.runtime.metrics.MetricsRecorder`), and return its record and its files' bytes
(nothing is written here). Pure functions of their inputs, so the local and Ray engines produce
the same bytes.
"""

from __future__ import annotations

import dataclasses
import functools
import io
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.apps.batch.plan import Job, OntoRig
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.ground import Ground
from ecs_anim.motion.clip import NormalizedMotion

if TYPE_CHECKING:
    from ecs_anim.io.export import Rig

F64 = NDArray[np.float64]

#: Foot-skate ratio (the motion-synthesis literature's definition, e.g. PhysDiff, GMD): a frame
#: skates when a foot (its toe joint, the ball of the foot) is under this height above the
#: ground and moves horizontally faster than :data:`SKATE_STEP_M` per 1/30 s.
SKATE_HEIGHT_M = 0.05
SKATE_STEP_M = 0.025
SKATE_REFERENCE_HZ = 30.0


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
    """A finished job: its record (see :func:`run_job`, :func:`failed_record`) and its files'
    bytes by path relative to the batch folder (empty when it failed)."""

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
            "floating_max_mm": None, "overlap_max_mm": None, "bone_error_m": None,
            "com_error_mm": None,
            "foot_skate_ratio": None, "seconds": round(seconds, 4), "outputs": [],
            "constraint_errors_mm": {}, "contacts": {"left": [], "right": []}}


def job_scenario(job: Job, motion: NormalizedMotion) -> Any:
    """The in-memory scenario of a job: the clip (motion name = the clip's name) on the body at
    the origin, facing +x, not looping, at the clip's rate for its length; or, with a template,
    the template's character, rate and length with the clip and body swapped in."""
    from ecs_anim.scenario import Scenario, clip_scenario

    t = job.template
    if t is None:
        scenario = clip_scenario(motion, job.body.morphology, job.ground.ground, job.clip,
                                 job.body.name, job.clip_path)
        return scenario if job.seconds is None else dataclasses.replace(scenario,
                                                                       duration_s=job.seconds)
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


@functools.lru_cache(maxsize=4)
def loaded_rig(onto: OntoRig) -> Rig:
    """The rig of ``onto``, loaded once per worker process (every job of a batch shares it)."""
    from ecs_anim.io.export import load_rig

    return load_rig(onto.path, onto.map_spec)


def job_files(job: Job, positions: F64, local: F64 | None, planted: NDArray[np.bool_],
              fps: float) -> dict[str, bytes]:
    """A job's files by path relative to the batch folder: each of its formats from the
    recorded ``positions`` (ticks, N_JOINTS, 3), export-skeleton ``local`` rotations (ticks, E,
    3, 3; None when no format needs them) and ``planted`` feet (ticks, 2), on the job's body,
    or retargeted onto its rig (:func:`~ecs_anim.io.export.recorded_on_rig`) with ``--onto``."""
    from ecs_anim.io.export import bvh_from_rotations, glb_bytes, write_npz

    morph = job.body.morphology
    files: dict[str, bytes] = {}
    if job.onto is not None:
        from ecs_anim.io.export import onto_rig_bytes, recorded_on_rig

        assert local is not None
        rig = loaded_rig(job.onto)
        lengths = np.broadcast_to(morph.lengths, (positions.shape[0], morph.lengths.shape[0]))
        pose = recorded_on_rig(rig, positions, local, lengths)
        return {f"{job.stem}.{ext}": onto_rig_bytes(rig, pose, ext, fps, planted)
                for ext in job.formats}
    for ext in job.formats:
        name = f"{job.stem}.{ext}"
        if ext == "npz":
            buffer = io.BytesIO()
            write_npz(buffer, positions, fps, planted)
            files[name] = buffer.getvalue()
            continue
        assert local is not None
        files[name] = bvh_from_rotations(morph, positions[:, 0], local, fps).encode("utf-8") \
            if ext == "bvh" else glb_bytes(morph, positions[:, 0], local, fps)
    return files


def run_job(job: Job, motion: NormalizedMotion) -> Outcome:
    """Play ``motion`` for ``job`` and return its record and files (nothing is written here).
    The simulation, metrics and encoders are those ``ecs-anim run --export`` uses."""
    from ecs_anim.runtime.metrics import MetricsRecorder
    from ecs_anim.scenario import build_simulation

    start = time.perf_counter()
    scenario = job_scenario(job, motion)
    ticks = round(scenario.duration_s * scenario.fps)
    if ticks < 1:
        raise EcsAnimError(f"--seconds {scenario.duration_s:g} is less than one tick at "
                           f"{scenario.fps:g} Hz")
    # (Onto a rig, the pelvis and thorax frames come from the rotations.)
    rotations = job.onto is not None or any(f in ("bvh", "glb") for f in job.formats)
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
    files = job_files(job, positions, local, planted, fps)
    character = report["characters"][0]
    record = {
        "clip": job.clip, "body": job.body.name, "ground": job.ground.name,
        "stature_m": round(morph.stature, 4), "frames": ticks, "status": "ok", "error": "",
        "duration_s": round(ticks / fps, 6),
        "slide_max_mm": character["foot_sliding_mm_per_frame"]["max"],
        "slide_mean_mm": character["foot_sliding_mm_per_frame"]["mean"],
        "penetration_max_mm": character["ground_penetration_mm_max"],
        "floating_max_mm": character["floating_mm_max"],
        "overlap_max_mm": max((c["overlap_mm_max"] for c in report["characters"]), default=0.0),
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


#: What an engine runs: clip path -> its jobs (each clip is imported once, for all its jobs).
WorkList = dict[str, list[Job]]
