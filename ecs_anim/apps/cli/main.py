"""The ``ecs-anim`` command line: its parser and :func:`main` (``import`` and ``info`` are in
:mod:`.import_cmd` and :mod:`.info`).

Every user error ends as one line on stderr and a non-zero exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from ecs_anim.apps.bench import cmd_bench, size_list
from ecs_anim.apps.cli.args import (
    EXIT_FAILED,
    add_rig_arguments,
    error_line,
    facing,
    frame_range,
    joined_axis_values,
    json_safe,
    length_unit,
    positive_float,
    positive_int,
    up_axis,
)
from ecs_anim.apps.cli.import_cmd import cmd_import
from ecs_anim.apps.cli.info import cmd_info
from ecs_anim.apps.viewer.command import add_arguments as add_view_arguments
from ecs_anim.apps.viewer.command import cmd_view
from ecs_anim.core.errors import EcsAnimError, listed
from ecs_anim.core.files import input_problem, output_folder_problem, output_problem
from ecs_anim.core.morphology import PRESET_SPECS
from ecs_anim.io.c3d.marker_sets import preset_summary as marker_set_summary
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.joint_presets import preset_summary
from ecs_anim.io.position_layouts import LAYOUTS
from ecs_anim.runtime.allocator import keep_freed_memory


def _children_cpu_s() -> float:
    """CPU seconds of this process's children that ended and were waited for."""
    import resource

    waited = resource.getrusage(resource.RUSAGE_CHILDREN)
    return waited.ru_utime + waited.ru_stime


#: Those before this program began: a shell's ``sh -c "pip install ... && ecs-anim run"``
#: becomes ``ecs-anim`` by exec and keeps its children's (the install's 17 s counted as the
#: first frame's).
_CHILDREN_CPU_AT_START_S = _children_cpu_s()

if TYPE_CHECKING:
    from ecs_anim.io.export.rig import Rig


def rig_inputs(args: argparse.Namespace) -> list[str]:
    """The files ``--onto RIG`` and ``--map FILE.yaml`` read (none without ``--onto``); a
    ``--map`` without ``--onto`` is refused."""
    from ecs_anim.io.export.rig import rig_input_files

    if args.onto is None:
        if args.map is not None:
            raise EcsAnimError(f"--map {args.map}: matches the joints of an --onto rig; give "
                               "--onto RIG")
        return []
    return rig_input_files(args.onto, args.map)


def onto_rig(args: argparse.Namespace) -> Rig | None:
    """The ``--onto`` rig with its ``--map``, loaded (None without ``--onto``)."""
    from ecs_anim.io.export import load_rig

    return None if args.onto is None else load_rig(args.onto, args.map)


def rig_summary(args: argparse.Namespace, rig: Rig | None) -> str:
    """`` onto RIG (N joints, how its joints were matched)``, or "" without a rig."""
    return "" if rig is None else f" onto {args.onto} ({rig.n_joints} joints, {rig.joint_map.how})"


def cmd_export(args: argparse.Namespace) -> int:
    from ecs_anim.io.export import export_motion
    from ecs_anim.motion.clip import load_nmo

    inputs = [args.file] if args.morphology == "source" or args.morphology in PRESET_SPECS \
        else [args.file, args.morphology]
    inputs += rig_inputs(args)
    problem = input_problem(args.output, inputs)
    if problem is not None:
        raise EcsAnimError(problem)
    motion = load_nmo(args.file)
    rig = onto_rig(args)
    morph, _ = export_motion(motion, args.morphology, args.output, force=args.force, onto=rig,
                             layout=args.layout)
    onto = rig_summary(args, rig)
    print(f"{args.file} on {morph.name} (stature {morph.stature:.3f} m){onto} -> {args.output}: "
          f"{motion.n_frames} frames")
    return 0


def use_threads(args: argparse.Namespace) -> None:
    """``--threads N``: the kernels' threads (:func:`ecs_anim.runtime.kernels.set_threads`; None:
    the idle cores, at least one: :func:`ecs_anim.runtime.kernels.default_threads`)."""
    from ecs_anim.runtime import kernels

    try:
        kernels.set_threads(args.threads)
    except ValueError as exc:
        raise EcsAnimError(f"--threads {args.threads}: {exc}") from None


#: The commands that run ticks in other processes (batch workers, the bench's sizes): they say
#: that the kernels compile before they start them. ``run`` and ``view`` say it on their first
#: tick, after their input was checked (an error comes alone).
EARLY_NOTICE_COMMANDS = ("batch", "bench")


def say_if_compiling(args: argparse.Namespace) -> None:
    """On a first run (the kernels not compiled yet): one line on stderr saying they are being
    compiled (once; cached in the user's cache folder), before the first tick."""
    from ecs_anim.runtime import kernels

    def say(notice: str) -> None:
        print(notice, file=sys.stderr, flush=True)

    if args.command in ("run", "view"):
        kernels.compile_aside()  # the first frame at once: numpy ticks while they compile
        kernels.announce_compiling(say)
    elif args.command in EARLY_NOTICE_COMMANDS and getattr(args, "what", "pipeline") == "pipeline":
        notice = kernels.compile_notice()
        if notice is not None:
            say(notice)


def cmd_view_threads(args: argparse.Namespace) -> int:
    """``view`` on ``--threads`` threads."""
    use_threads(args)
    return cmd_view(args)


def cmd_run(args: argparse.Namespace) -> int:
    from ecs_anim.runtime.simulation import MAX_DURATION_S
    from ecs_anim.scenario import build_simulation, load_scenario

    use_threads(args)

    if args.report is not None and Path(args.report).suffix.lower() != ".json":
        raise EcsAnimError(f"--report {args.report}: a report is JSON: name it .json")
    scenario = load_scenario(args.scenario)
    seconds = scenario.duration_s if args.seconds is None else args.seconds
    problems: list[tuple[str, str | None]] = []
    rig_files = rig_inputs(args)
    if rig_files and not args.export:
        raise EcsAnimError(f"--onto {args.onto}: the rig the export is written onto; give "
                           "--export DIR")
    if args.export:
        problems += [("--export", input_problem(args.export, [*scenario.input_files, *rig_files],
                                                folder=True)),
                     ("--export", output_folder_problem(args.export, _export_names(scenario),
                                                        args.force))]
    if args.report:
        problems += [("--report", input_problem(args.report, scenario.input_files)),
                     ("--report", output_problem(args.report, args.force))]
        if args.export and Path(os.path.realpath(args.report)).is_relative_to(
                os.path.realpath(args.export)):
            problems.append(("--report", (f"{args.report}: inside the --export folder, which an "
                                          "export replaces as a whole; write it elsewhere")))
    for flag, problem in problems:  # before any work: a run can last minutes
        if problem is not None:
            raise EcsAnimError(f"{flag} {problem}")
    if seconds > MAX_DURATION_S:
        raise EcsAnimError(f"--seconds {seconds:g}: at most {MAX_DURATION_S:g} s (a day) in one run")
    ticks = round(seconds * scenario.fps)
    if ticks < 1:
        raise EcsAnimError(f"--seconds {seconds:g} is less than one tick at {scenario.fps:g} Hz")
    rig = onto_rig(args)  # before the run: a rig it cannot use is said at once
    with build_simulation(scenario, rotations=bool(args.export)) as sim:
        return _run_and_write(args, scenario, sim, ticks, seconds, rig)


def _export_names(scenario) -> list[str]:  # type: ignore[no-untyped-def]
    """The files ``run --export`` writes: a ``.bvh``, an ``.npz`` and a ``.glb`` per character."""
    return [f"{c.name}.{ext}" for c in scenario.characters for ext in ("bvh", "npz", "glb")]


def _run_and_write(args: argparse.Namespace, scenario, sim, ticks: int,  # type: ignore[no-untyped-def]
                   seconds: float, rig: Rig | None) -> int:
    """Run, then write the export folder as one set (the simulation's recorder,
    :meth:`~ecs_anim.runtime.recorder.Recorder.save`, onto ``rig`` if given) and after it the
    report, then print the metrics."""
    from ecs_anim.core.files import atomic_output
    from ecs_anim.runtime.feasibility import feasibility_lines, ground_lines
    from ecs_anim.runtime.metrics import MetricsRecorder

    names = [c.name for c in scenario.characters]
    metrics = MetricsRecorder(sim)
    recorder = sim.record() if args.export else None
    reach = sim.feasibility()
    ground = ground_lines(sim)
    for line in ground + feasibility_lines(reach):  # before the first tick: a run can last minutes
        print(line, flush=True)
    timing = TickTimes(sim)
    for _ in range(ticks):
        with timing.tick():
            sim.step()
        metrics.record()
    report = metrics.report() | {"scenario": str(args.scenario),
                                 "feasibility": [estimate.as_dict() for estimate in reach],
                                 "ground_problems": ground, "timing": timing.as_dict()}
    unposed = []  # characters removed before their first posture: no files
    if recorder is not None:
        written = {path.name for path in recorder.save(args.export, force=args.force, onto=rig)}
        unposed = [name for name in names if f"{name}.bvh" not in written]
    if args.report:
        with atomic_output(args.report, args.force) as f:
            f.write(json.dumps(json_safe(report), indent=2, allow_nan=False).encode("utf-8"))
    print(f"{args.scenario}: {ticks} ticks ({seconds:g} s at {scenario.fps:g} Hz), "
          f"{len(names)} characters")
    print(f"  {'character':14s} {'float mm':>8s} {'penetr. mm':>10s} {'slide max mm/fr':>15s} "
          f"{'bone err m':>10s} {'stride/leg':>10s} {'COM err mm':>10s} {'overlap mm':>10s} "
          f"{'joint m/s (clip)':>16s}")
    for c in report["characters"]:
        stride = "-" if c["stride_per_leg_length"] is None else f"{c['stride_per_leg_length']:.3f}"
        com = "-" if c["com_error_mm_max"] is None else f"{c['com_error_mm_max']:.1f}"
        removed = "" if "removed_at_s" not in c else f"  (removed at {c['removed_at_s']:g} s)"
        # floating first: a planted foot held in the air slides nowhere and sinks nowhere
        print(f"  {c['name'][:14]:14s} {c['floating_mm_max']:8.3f} "
              f"{c['ground_penetration_mm_max']:10.3f} {c['foot_sliding_mm_per_frame']['max']:15.3f} "
              f"{c['bone_length_error_m_max']:10.1e} {stride:>10s} {com:>10s} "
              f"{c['overlap_mm_max']:10.1f} "
              f"{c['joint_speed_m_s_max']:7.2f} ({c['clip_joint_speed_m_s_max']:5.2f}){removed}")
    if report["constraints"]:
        # While a constraint eases in or out its goal is a blend, so its error against the full
        # target says nothing; the report's JSON has both.
        print(f"  {'constraint':26s} {'max error mm while fully active':>32s}")
        for k in report["constraints"]:
            full = k["error_mm_max_fully_active"]
            unit = " mrad" if k["unit"] == "mrad" else ""
            text = "never fully active" if full is None else f"{full:.1f}{unit}"
            print(f"  {(k['character'] + '.' + k['name'])[:26]:26s} {text:>32s}"
                  + ("" if k["enabled"] else "  (switched off: target not finite or beyond 1,000 km)"))
    for line in timing.lines():
        print(f"  {line}")
    if args.export:
        print(f"  wrote {len(names) - len(unposed)} x (.bvh, .npz, .glb){rig_summary(args, rig)} "
              f"to {args.export}"
              + (f" (none for {listed(unposed)}: removed before the first tick's posture)"
                 if unposed else ""))
    if args.report:
        print(f"  wrote report {args.report}")
    return 0


class TickTimes:
    """``run``'s timing: each tick's wall time, the systems' time once warm (the ticks on the
    kernels after the first of them), and what the kernels cost apart
    (:data:`ecs_anim.runtime.kernels.load_figures`: compiled on a first run, else loaded). On a
    first run the kernels compile aside: the ticks until they are in the cache run on numpy,
    counted apart."""

    def __init__(self, sim) -> None:  # type: ignore[no-untyped-def]
        self.sim = sim
        self.tick_ms: list[float] = []
        self.numpy_ms: list[float] = []  # the ticks on the numpy references (a first run)
        self._kernels: dict[str, float | bool] = {}
        self._warm_from: dict[str, float] = {}
        self._warm_ticks = -1  # the ticks on the kernels, less the first of them
        #: CPU seconds from the process start to the end of the first tick: this process's
        #: and its children's it waited for (a child compiling aside is not: it runs apart).
        self.first_frame_cpu_s: float | None = None

    @contextmanager
    def tick(self) -> Iterator[None]:
        start = time.perf_counter()
        yield
        ms = (time.perf_counter() - start) * 1e3
        self.tick_ms.append(ms)
        if self.first_frame_cpu_s is None:
            self.first_frame_cpu_s = time.process_time() + _children_cpu_s() - _CHILDREN_CPU_AT_START_S
        if not self.sim.compiled:
            self.numpy_ms.append(ms)
            return
        self._warm_ticks += 1
        if self._warm_ticks == 0:
            self._warm_from = self.sim.system_seconds()

    @property
    def kernels(self) -> dict[str, float | bool]:
        """What the kernels cost this process (once they are in memory; empty if they were
        already, or are still compiling aside)."""
        from ecs_anim.runtime import kernels

        if not self._kernels:
            self._kernels = kernels.new_load_figures()
        return self._kernels

    def warm_ms_per_tick(self) -> dict[str, float]:
        """Each system's mean ms per tick on the kernels, after the first such tick (empty for
        fewer than two)."""
        if self._warm_ticks < 1:
            return {}
        return {k: (v - self._warm_from[k]) / self._warm_ticks * 1e3
                for k, v in self.sim.system_seconds().items()}

    def as_dict(self) -> dict[str, object]:
        """The report's ``timing``: ms (wall) of the first tick and the CPU seconds from the
        process start to its end, the median and slowest of the
        warm ones (on the kernels, after the first of them), each system's mean over those, the
        kernels' load (or compile) s and CPU s, and the ticks run on numpy while they compiled
        aside (their count and median ms)."""
        from ecs_anim.runtime import kernels

        warm = self.tick_ms[len(self.numpy_ms) + 1:]
        figures = self.kernels
        return {"first_tick_ms": round(self.tick_ms[0], 3) if self.tick_ms else None,
                "first_frame_cpu_s": (None if self.first_frame_cpu_s is None
                                      else round(self.first_frame_cpu_s, 3)),
                "warm_tick_ms_median": round(statistics.median(warm), 3) if warm else None,
                "warm_tick_ms_max": round(max(warm), 3) if warm else None,
                "warm_ms_per_tick": {k: round(v, 4) for k, v in self.warm_ms_per_tick().items()},
                "kernels_s": round(float(figures["seconds"]), 3) if figures else 0.0,
                "kernels_cpu_s": round(float(figures["cpu_seconds"]), 3) if figures else 0.0,
                "kernels_compiled": bool(figures.get("compiled", False)),
                "kernels_still_compiling": kernels.kernels_pending(),
                "numpy_ticks": len(self.numpy_ms),
                "numpy_tick_ms_median": (round(statistics.median(self.numpy_ms), 3)
                                         if self.numpy_ms else None)}

    def lines(self) -> list[str]:
        d = self.as_dict()
        figures = self.kernels
        if d["numpy_ticks"]:
            kernels = (f"; ticks 1-{d['numpy_ticks']} on numpy (median "
                       f"{d['numpy_tick_ms_median']:.2f} ms) while the kernels compiled aside, "
                       + ("still compiling at the end: the next run loads them"
                          if d["kernels_still_compiling"] else
                          f"in {d['kernels_s']:.1f} s"
                          + (f" ({d['kernels_cpu_s']:.1f} s of CPU)" if figures.get("ours")
                             else " (by another run's process)")))
        elif figures:
            kernels = (f"; kernels {'compiled' if d['kernels_compiled'] else 'loaded'} in "
                       f"{d['kernels_s']:.1f} s before it ({d['kernels_cpu_s']:.1f} s of CPU)")
        else:
            kernels = ""
        out = [f"first tick {d['first_tick_ms']:.2f} ms, at {d['first_frame_cpu_s']:.2f} s of CPU "
               f"from the start{kernels}"]
        systems = self.warm_ms_per_tick()
        if systems:
            out.append(f"time per tick once warm {sum(systems.values()):.2f} ms (median tick "
                       f"{d['warm_tick_ms_median']:.2f} ms, slowest {d['warm_tick_ms_max']:.2f} ms): "
                       + ", ".join(f"{k} {v:.2f}" for k, v in systems.items()))
        return out


def add_threads_argument(p: argparse.ArgumentParser, default: int | None) -> None:
    """``--threads N``: how many threads the kernels run on (None: the idle cores, at least
    one)."""
    p.add_argument("--threads", type=positive_int, default=default, metavar="N",
                   help="threads the tick's kernels run on "
                   + ("(default: the cores the machine leaves idle, at least one)"
                      if default is None
                      else f"(default {default}: the figures per core)"))


def build_parser() -> argparse.ArgumentParser:
    from ecs_anim.io.c3d.repair import DEFAULT_MAX_GAP_S

    parser = argparse.ArgumentParser(
        prog="ecs-anim",
        description="Morphology-independent motions for many characters (Kulpa et al. 2005).",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("import", help="normalize captured clips (BVH, C3D, FBX, joint positions) "
                       "into .nmo files",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="joint-name presets (BVH):\n" + preset_summary()
                       + "\nmarker sets (C3D):\n" + marker_set_summary())
    p.add_argument("sources", nargs="+", metavar="SRC", help="BVH, C3D or FBX files, or joint "
                   "positions (.npy, .npz, MediaPipe .json or .csv)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="folder for .nmo files")
    p.add_argument("--map", metavar="PRESET|FILE.yaml", help="joint-name preset or YAML map "
                   "(BVH), marker-set preset or YAML marker map (C3D) (default: detect)")
    p.add_argument("--unit", type=length_unit, metavar="m|cm|mm|inch|cmu|METRES",
                   help="length unit of the file: a name, or for BVH metres per file unit "
                   "(0.0254) (default: detected from the proportions)")
    p.add_argument("--stature", type=positive_float, metavar="M",
                   help="BVH: scale the source so that its body is M metres tall (a rig "
                   "scaled by its tool, a child whose unit the proportions cannot tell)")
    p.add_argument("--up", type=up_axis, default=None, metavar="x|y|z|-x|-y|-z",
                   help="the file's up axis, the way from the feet to the head; -y for a file "
                   "upside down (Y pointing down, as in images) (default: detected from the rest "
                   "pose and the motion, head above the feet, for BVH; from the markers for C3D)")
    p.add_argument("--face", type=facing, metavar="+x|-x|+y|-y|DEGREES",
                   help="turn each clip about its origin so that it faces this way at its first "
                   "frame (degrees anticlockwise from +x), as our motion library does; "
                   "--constraints are then given in the turned clip's frame")
    p.add_argument("--trim", type=frame_range, metavar="START:END",
                   help="keep only these frames of each file: frame numbers (START included, END "
                   "not; negative from the end; either may be left out, e.g. 1: drops a first "
                   "frame) or seconds with s (0.5s:12s). Without it a rest pose (T-pose) before "
                   "the motion is dropped, and said; 0: keeps it")
    p.add_argument("--layout", metavar="|".join(LAYOUTS),
                   help="joint positions (.npy, .npz, .json, .csv): the layout of the joints "
                   "(default: detected from the joint count or names; 22 joints need it)")
    p.add_argument("--fps", type=positive_float, metavar="F",
                   help="frames per second where a file may give none: joint positions "
                   "(default: the file's, else the layout's dataset rate: humanml3d 20, kit "
                   "12.5), .amc and AMASS files (docs/import.md)")
    p.add_argument("--lowpass", type=positive_float, metavar="HZ",
                   help="joint positions: smooth jitter with a zero-lag low-pass at this "
                   "cut-off (default: off, for mocap-grade data; 6 for a video estimator's)")
    p.add_argument("--body-model", metavar="MODEL.npz|SKELETON.asf|MODEL.osim",
                   help="AMASS .npz: your SMPL, SMPL-H or SMPL-X body model (.npz; licensed, not "
                   "shipped: docs/import.md says where to get it); .amc: its ASF skeleton "
                   "(default: the .asf beside it); OpenSim .mot/.sto joint angles: the .osim "
                   "model they were computed on")
    p.add_argument("--take", metavar="NAME",
                   help="FBX: the animation stack (take) to import (default: the first; the "
                   "import says which others the file has)")
    p.add_argument("--max-gap", type=positive_int, metavar="FRAMES",
                   help="C3D: longest run of missing marker samples filled without a warning "
                   f"(default: {DEFAULT_MAX_GAP_S:g} s at the file's rate, 10 at 100 Hz)")
    p.add_argument("--fill-absent-from", metavar="MOTION.nmo|MOTION.bvh",
                   help="C3D: take body parts with no markers from this motion (looped) instead "
                   "of a neutral pose")
    p.add_argument("--constraints", metavar="FILE.yaml",
                   help="constraints to store with every imported motion (e.g. two hands in "
                        "contact during a clap), times in the motion's own seconds; see "
                        "docs/scenarios.md")
    p.add_argument("--contact-height", type=positive_float, default=ContactThresholds.height_m,
                   metavar="M", help="foot-contact height above the local ground under the foot, m, "
                   "for a 0.8 m leg, scaled by the body's (default %(default)s)")
    p.add_argument("--contact-speed", type=positive_float, default=None, metavar="M/S",
                   help="foot-contact speed threshold, m/s (default: relative to the body and "
                   "the clip's own motion)")
    p.add_argument("--contacts", choices=["detect", "events"], default="detect",
                   help="foot contacts detected from the feet's stillness (default), or C3D: "
                   "taken from the file's gait events (EVENT group: foot strike to foot off)")
    p.add_argument("--no-treadmill", action="store_true",
                   help="keep an in-place clip in place: by default a stance foot sliding back "
                   "under a still root, as on a treadmill, becomes root motion (reported)")
    p.add_argument("--contact-min-duration", type=positive_float, default=ContactThresholds.min_duration_s,
                   metavar="S", help="shortest contact kept, s (default %(default)s)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("info", help="describe .nmo files (several, or a folder: a table)")
    p.add_argument("file", metavar="FILE.nmo|FOLDER", nargs="+")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("export", help="play a .nmo on a body and write BVH, glTF or joint positions")
    p.add_argument("file", metavar="FILE.nmo")
    p.add_argument("--morphology", default="source",
                   help=f"source | {' | '.join(PRESET_SPECS)} | FILE.yaml | SKELETON.bvh "
                        "(default: source)")
    add_rig_arguments(p, "the motion")
    p.add_argument("--layout", metavar="|".join(LAYOUTS),
                   help="write the joints of this research layout, in its order, axes and unit, "
                        "to OUT.npy or OUT.npz (docs/export.md)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.bvh|OUT.npz|OUT.glb|OUT.npy")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("run", help="run a scenario headless; print metrics, optionally export")
    p.add_argument("scenario", metavar="SCENARIO.yaml")
    p.add_argument("--seconds", type=positive_float, help="run this long instead of duration_s")
    p.add_argument("--export", metavar="DIR", help="write <character>.bvh, .npz and .glb per character")
    add_rig_arguments(p, "with --export: each character")
    p.add_argument("--report", metavar="FILE.json", help="write the metrics as JSON")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    add_threads_argument(p, None)
    p.set_defaults(func=cmd_run)

    from ecs_anim.apps.batch.command import add_parser as add_batch_parser

    add_batch_parser(sub)

    p = sub.add_parser("bench", help="print performance figures (default: the pipeline)")
    p.add_argument("what", nargs="?", choices=["pipeline", "import"], default="pipeline",
                   help="pipeline: characters per tick; import: parse+FK+encode frames/s")
    p.add_argument("files", nargs="*", help="import: clips (default: ../shared/mocap, else the "
                   "shipped motions); the largest is measured")
    p.add_argument("--characters", type=positive_int, default=400, metavar="N",
                   help="pipeline: characters (default %(default)s)")
    p.add_argument("--seconds", type=positive_float, default=3.0, metavar="S",
                   help="pipeline: simulated seconds to time (default %(default)s)")
    p.add_argument("--constrained", action="store_true",
                   help="pipeline: each character also has a wrist and an elbow target its right "
                        "arm takes, moving with it; prints the errors reached")
    p.add_argument("--crossing", action="store_true",
                   help="pipeline: the walkers cross each other (about a tenth of them in "
                        "someone's body every tick: CollisionSeparate's worst case) instead of "
                        "walking in lanes")
    p.add_argument("--peer-task", action="store_true",
                   help="pipeline: instead, the IK comparisons' wrist-elbow-feet-COM task on one "
                        "body: its errors and how far the shoulder moved")
    p.add_argument("--rotations", action="store_true",
                   help="pipeline: also compute local joint rotations every tick (as BVH export does)")
    p.add_argument("--budget-ms", type=positive_float, metavar="MS",
                   help="pipeline, with --constrained: the tick's frame budget (CPU ms a tick); "
                        "prints the cut tick by tick and how many characters it holds")
    p.add_argument("--sizes", type=size_list, metavar="N,N,...",
                   help="pipeline: the numbers of characters timed (default: N/8, N/4, N/2, N)")
    p.add_argument("--no-compile-timing", action="store_true",
                   help="pipeline: skip timing a start with an empty kernel cache and one with "
                   "the cache filled (a fresh compile: docs/performance.md)")
    add_threads_argument(p, 1)
    p.add_argument("--repeat", type=positive_int, default=3, help="import: runs; the best is kept")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("view", help="watch a scenario in a window, or render one frame to a PNG")
    add_view_arguments(p)
    add_threads_argument(p, None)
    p.set_defaults(func=cmd_view_threads)
    return parser


class WarningLines(logging.Handler):
    """The command line's run-time warnings (the ``ecs_anim`` logger): each one line on the
    standard error of the moment (a test's captured one too)."""

    def emit(self, record: logging.LogRecord) -> None:
        print(record.getMessage(), file=sys.stderr)


def show_warnings() -> None:
    """Print the library's warnings as lines on stderr, once per process."""
    log = logging.getLogger("ecs_anim")
    if not any(isinstance(h, WarningLines) for h in log.handlers):
        log.addHandler(WarningLines(logging.WARNING))  # Python's last resort then stays silent


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(joined_axis_values(list(sys.argv[1:] if argv is None else argv)))
    show_warnings()
    keep_freed_memory()  # an application's choice (it changes the process's allocator)
    try:
        say_if_compiling(args)
        return int(args.func(args))
    except (EcsAnimError, FileExistsError) as exc:
        print(f"error: {error_line(exc)}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (``| head``): stop quietly, as Unix tools do
        # (Python's documented recipe: point stdout at devnull so the exit flush cannot fail.)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILED
    except OSError as exc:  # an unreadable input, ...: say which file
        print(f"error: {error_line(exc)}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        from ecs_anim.runtime import kernels

        kernels.announce_compiling(None)  # a command that never ticked leaves nothing behind
        kernels.compile_aside(False)


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["build_parser", "main"]
