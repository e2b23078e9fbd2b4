"""The ``ecs-anim batch`` command: its arguments, the plan they give (from the flags or a
manifest), and the run with its summary line.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path
from typing import Any

from ecs_anim.apps.batch.driver import run_batch
from ecs_anim.apps.batch.job_hash import files_digest
from ecs_anim.apps.batch.manifest import load_manifest
from ecs_anim.apps.batch.plan import DEFAULT_FORMATS, Body, OntoRig, Plan, make_plan
from ecs_anim.apps.batch.plan_parts import (
    CLIP_TYPES,
    body_from_text,
    expand_clips,
    load_grounds,
    load_template,
    parse_formats,
)
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import PRESET_SPECS


def plan_from_args(args: argparse.Namespace) -> Plan:
    """The plan from the command line, or from ``--manifest`` (the command line's ``--out``,
    ``--formats``, ``--seconds`` and ``--onto`` with its ``--map`` override the manifest's)."""
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
    if args.onto is not None:
        parts["onto"] = (args.onto, args.map)
    elif args.map is not None:
        raise EcsAnimError(f"--map {args.map}: matches the joints of an --onto rig; give --onto RIG")
    onto = None
    if "onto" in parts:
        from ecs_anim.io.export.rig import rig_input_files

        onto = onto_rig(*parts["onto"])
        inputs += rig_input_files(onto.path, onto.map_spec)
    return make_plan(parts["clips"], parts["bodies"], parts["out"], parts.get("grounds"),
                     parts.get("formats", DEFAULT_FORMATS), parts.get("template"),
                     parts.get("seconds"), inputs, onto)


def onto_rig(path: str, map_spec: str | None) -> OntoRig:
    """The ``--onto`` rig of a batch, loaded once here so that a rig no job could use is said
    before any job runs; its hash is of its files' bytes and the map."""
    from ecs_anim.io.export.rig import load_rig, rig_input_files

    load_rig(path, map_spec)
    files = files_digest(rig_input_files(path, map_spec))
    return OntoRig(str(path), map_spec, hashlib.sha256(f"{files}\0{map_spec}".encode()).hexdigest())


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
    from ecs_anim.apps.cli.args import add_rig_arguments, positive_float, positive_int

    p = subparsers.add_parser(
        "batch", help="play many clips on many bodies over many grounds; metrics and a report",
        description="Every clip x body x ground as a job, in parallel; outputs "
                    "DIR/<clip>/<body>[_<ground>].{bvh,npz,glb}, DIR/metrics.csv, metrics.json "
                    "and report.html. A second run skips jobs done with the same inputs.")
    p.add_argument("clips", nargs="*", metavar="CLIP",
                   help=f"clips: {CLIP_TYPES} files, globs ('mocap/*.bvh') or folders")
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
    add_rig_arguments(p, "every job")
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
