"""``ecs-anim import``: BVH, C3D, FBX and joint-position files to normalized motions (.nmo),
one line each."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from ecs_anim.apps.cli.args import EXIT_FAILED, error_line
from ecs_anim.core.errors import EcsAnimError, listed
from ecs_anim.core.files import folder_problem, input_problem
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.position_files import POSITION_SUFFIXES
from ecs_anim.motion.clip import turned_to_face
from ecs_anim.motion.constraint_table import check_stored


def _progress(done: int, total: int, label: str) -> None:
    """A one-line progress bar on stderr (only drawn when several files are processed)."""
    width = 30
    filled = int(width * done / max(total, 1))
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {label[:40]:40s}")
    if done == total:
        sys.stderr.write("\n")
    sys.stderr.flush()


def cmd_import(args: argparse.Namespace) -> int:
    """``ecs-anim import``: each source to ``-o DIR/<stem>.nmo``; a bad file fails alone
    (exit status :data:`~ecs_anim.apps.cli.args.EXIT_FAILED` when any did)."""
    from ecs_anim.io.acclaim import import_amc
    from ecs_anim.io.c3d.importing import import_c3d
    from ecs_anim.io.fbx import import_fbx
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.io.opensim_mot import import_mot, refuse_mot
    from ecs_anim.io.positions import PositionOptions, import_positions
    from ecs_anim.io.smpl import import_amass, is_amass
    from ecs_anim.io.trc import import_trc
    from ecs_anim.motion.clip import save_nmo

    outdir = Path(args.output)
    problem = folder_problem(outdir)
    if problem is not None:
        raise EcsAnimError(f"-o {problem}")
    thresholds = ContactThresholds(
        height_m=args.contact_height, speed_mps=args.contact_speed,
        min_duration_s=args.contact_min_duration,
    )
    extra = []
    if args.constraints:
        from ecs_anim.scenario import load_motion_constraints
        extra = load_motion_constraints(args.constraints)  # a mistake stops before any import
    sources = [Path(s) for s in args.sources]
    inputs = [*sources, *(p for p in (args.map, args.constraints, args.fill_absent_from) if p)]
    for src in sources:
        problem = input_problem(outdir / f"{src.stem}.nmo", inputs)
        if problem is not None:
            raise EcsAnimError(f"-o {problem}")
    if not any(s.suffix.lower() in (".c3d", ".trc") for s in sources) and (
            args.fill_absent_from or args.max_gap is not None):
        raise EcsAnimError("--max-gap and --fill-absent-from are for .c3d and .trc files; none "
                           "is given")
    if args.body_model and not any(s.suffix.lower() in (".amc", ".npz", ".mot", ".sto")
                                   for s in sources):
        raise EcsAnimError("--body-model is for AMASS .npz motions (a SMPL body model), .amc "
                           "motions (their .asf skeleton) and OpenSim .mot/.sto joint angles "
                           "(their .osim model); none is given")
    # The ASF skeleton of .amc files, or the SMPL body model of AMASS files.
    asf = args.body_model if args.body_model and args.body_model.lower().endswith(".asf") else None
    osim = args.body_model if args.body_model and args.body_model.lower().endswith(".osim") \
        else None
    body_model = args.body_model if args.body_model and asf is None and osim is None else None
    if args.take is not None and not any(s.suffix.lower() == ".fbx" for s in sources):
        raise EcsAnimError("--take is for .fbx files; none is given")
    positions = [s for s in sources if s.suffix.lower() in POSITION_SUFFIXES]
    amc = any(s.suffix.lower() == ".amc" for s in sources)  # an AMC stores no rate: --fps
    if not positions and (args.layout or (args.fps and not amc) or args.lowpass):
        raise EcsAnimError("--layout, --fps and --lowpass are for joint positions (.npy, .npz, "
                           ".json, .csv); none is given")
    if positions and args.map:
        raise EcsAnimError(f"--map is for BVH, C3D and FBX files; the joints of {positions[0]} "
                           "are named by --layout")
    failed = 0
    show_bar = len(sources) > 1 and sys.stderr.isatty()
    stems: dict[str, Path] = {}
    for k, src in enumerate(sources, start=1):
        target = outdir / f"{src.stem}.nmo"
        try:
            if src.stem in stems:
                raise EcsAnimError(f"{src}: has the same name as {stems[src.stem]}; both would be "
                                   f"written to {target}")
            stems[src.stem] = src
            if target.exists() and not args.force:
                raise EcsAnimError(f"{target}: already exists (use --force to overwrite)")
            suffix = src.suffix.lower()
            if src.is_dir():
                raise EcsAnimError(f"{src}: a folder; give the .bvh, .c3d or .fbx files in it "
                                   f"(e.g. {src}/*.bvh)")
            if suffix in (".mot", ".sto") and osim is None:
                raise refuse_mot(src)
            if suffix == ".osim":
                raise EcsAnimError(f"{src}: an OpenSim model holds no motion; import its .mot "
                                   f"joint angles with --body-model {src}")
            if suffix == ".asf":
                raise EcsAnimError(f"{src}: an ASF holds a skeleton only; import its .amc "
                                   "motions (the .asf beside them is found, or give it with "
                                   "--body-model)")
            if suffix not in (".bvh", ".c3d", ".fbx", ".trc", ".amc", ".mot", ".sto",
                              *POSITION_SUFFIXES):
                raise EcsAnimError(f"{src}: unsupported file type {src.suffix!r} (expected .bvh, "
                                   f".c3d, .fbx, .trc, .amc, .mot, AMASS .npz or joint positions "
                                   f"{', '.join(POSITION_SUFFIXES)})")
            if suffix in (".c3d", ".trc") and args.stature is not None:
                raise EcsAnimError(f"{src}: --stature applies to BVH files (markers are in the "
                                   "file's unit: a C3D's POINT:UNITS, a TRC's Units)")
            if suffix in POSITION_SUFFIXES and args.stature is not None:
                raise EcsAnimError(f"{src}: --stature applies to BVH files (joint positions: "
                                   "--unit)")
            if suffix == ".c3d":
                motion = import_c3d(src, args.map, args.unit, thresholds, args.up,
                                    args.max_gap,
                                    args.fill_absent_from, args.trim, not args.no_treadmill,
                                    args.contacts)
            elif suffix == ".trc":
                if args.contacts == "events":
                    raise EcsAnimError(f"{src}: --contacts events needs a C3D file's gait events "
                                       "(a TRC file has none)")
                motion = import_trc(src, args.map, args.unit, thresholds, args.up, args.max_gap,
                                    args.fill_absent_from, args.trim, not args.no_treadmill)
            else:
                if args.contacts == "events":
                    raise EcsAnimError(f"{src}: --contacts events needs a C3D file's gait events "
                                       f"(a {suffix[1:].upper()} file has none)")
                if suffix == ".fbx":
                    motion = import_fbx(src, args.map, args.unit, thresholds, args.up, args.trim,
                                        args.stature, not args.no_treadmill, args.take)
                elif suffix in (".mot", ".sto"):
                    assert osim is not None
                    given = [flag for flag, value in (("--map", args.map), ("--unit", args.unit),
                                                      ("--up", args.up),
                                                      ("--stature", args.stature)) if value]
                    if given:
                        verb = "does" if len(given) == 1 else "do"
                        raise EcsAnimError(f"{src}: {', '.join(given)} {verb} not apply to OpenSim "
                                           "joint angles (the model is in metres, Y up, and its "
                                           "bodies are the joints)")
                    motion = import_mot(src, osim, thresholds, args.trim, not args.no_treadmill)
                elif suffix == ".amc":
                    motion = import_amc(src, asf, args.map, args.unit, thresholds, args.up,
                                        args.trim, args.stature, not args.no_treadmill, args.fps)
                elif suffix == ".npz" and (body_model or is_amass(src)):
                    if body_model is None:
                        raise EcsAnimError(f"{src}: an AMASS/SMPL motion (poses, trans): its "
                                           "joints come from a body model; give --body-model "
                                           "MODEL.npz (SMPL, SMPL-H or SMPL-X: docs/import.md "
                                           "says where to get one)")
                    motion = import_amass(src, body_model, thresholds, args.up, args.trim,
                                          not args.no_treadmill, args.fps)
                elif suffix in POSITION_SUFFIXES:
                    options = PositionOptions(args.layout, args.fps, args.up, args.unit,
                                              args.lowpass)
                    motion = import_positions(src, options, thresholds, args.trim,
                                              not args.no_treadmill)
                else:
                    motion = import_bvh(src, args.map, args.unit, thresholds, args.up, args.trim,
                                        args.stature, not args.no_treadmill)
                for warning in motion.info.get("warnings", []):
                    print(f"warning: {warning}", file=sys.stderr)
            if args.face is not None:
                motion = turned_to_face(motion, args.face)
            # A --constraints file times the file's frames; --trim or a C3D import may drop some.
            shift_s = motion.info.get("first_file_frame", 0) / motion.fps
            on_clip = [replace(c, activation=replace(c.activation, start_s=c.activation.start_s - shift_s,
                                                     stop_s=c.activation.stop_s - shift_s))
                       for c in extra] if shift_s else extra
            motion.constraints.extend(on_clip)
            try:
                check_stored(on_clip, motion.duration_s)
            except ValueError as exc:
                raise EcsAnimError(f"{args.constraints}: with {src}: {exc}") from None
            save_nmo(motion, target, force=args.force)
            contacts = motion.contacts()
            message = (f"{src} -> {target}: {motion.n_frames} frames at {motion.fps:g} fps, "
                       f"{motion.info['joint_map']}, {motion.info['up_axis'].upper()} up"
                       + (f" ({motion.info['up_reason']})" if motion.info.get("up_reason") else "")
                       + ", unit "
                       f"{motion.info['unit']} ({motion.info['unit_reason']}), "
                       f"contacts L {contacts[:, 0].mean():.0%} "
                       f"R {contacts[:, 1].mean():.0%}"
                       + (" (from the gait events)" if motion.info.get("contacts", {}).get("method")
                          == "gait events" else ""))
            message += _events_and_treadmill(motion.info) + _positions_read(motion.info)
            if motion.info.get("fbx"):
                message += f", take {motion.info['fbx']['take']!r}"
                others = len(motion.info["fbx"]["takes"]) - 1
                if others:
                    message += f" (the file has {others} other{'s' * (others != 1)}: --take NAME)"
            if motion.info["filled_in"]:
                message += f", filled in: {', '.join(motion.info['filled_in'])}"
            if motion.info.get("ignored_joints"):
                message += f", ignored (no body part): {listed(motion.info['ignored_joints'])}"
            if extra:
                message += f", {len(extra)} stored constraint(s)"
            if motion.info.get("absent"):
                message += (f", absent ({motion.info['absent_fill']}): "
                            f"{', '.join(motion.info['absent'])}")
            gaps = motion.info.get("gaps")
            if gaps:
                message += f", {gaps['samples_filled']} marker samples filled"
                if gaps["long_gap_frames"]:
                    spans = ", ".join(f"{a}-{b}" for a, b in gaps["long_gap_frames"])
                    message += (f"; frames {spans} had gaps longer than {gaps['max_gap_frames']} "
                                "frames or markers not yet or no longer seen (interpolated or "
                                "held, unreliable)")
            if args.trim is not None:
                message += f"; --trim kept frames from frame {motion.info.get('first_file_frame', 0)} of the file"
            if motion.info.get("glitch_frames"):
                message += f"; {motion.info['glitch_frames']}"
            if motion.info.get("rest_frames_dropped"):
                message += f"; {motion.info['rest_frames_dropped']}"
            if motion.info.get("filled_legs_resized"):
                message += f"; {motion.info['filled_legs_resized']}"
            for key, what in (("root_frames_trimmed", "trimmed (of the file's frames)"),
                              ("root_frames_repaired", "repaired")):
                if motion.info.get(key):
                    spans = ", ".join(f"{a}-{b}" for a, b in motion.info[key])
                    message += f"; frames {spans} {what}: the pelvis markers could not place the pelvis"
            for line in motion.info.get("parts_frames_trimmed") or []:
                message += f"; {line}"
            if show_bar:
                sys.stderr.write("\r" + " " * 80 + "\r")
            print(message)
            for why in (motion.info.get("parts_not_computed") or {}).values():
                print(f"  {why}")
        except (EcsAnimError, OSError) as exc:  # one bad file must not stop the others
            failed += 1
            if show_bar:
                sys.stderr.write("\r" + " " * 80 + "\r")
            print(f"error: {error_line(exc)}", file=sys.stderr)
        if show_bar:
            _progress(k, len(sources), src.name)
    if failed:
        rest = "; the others were imported" if failed < len(sources) else ""
        print(f"{failed} of {len(sources)} file(s) failed{rest}", file=sys.stderr)
        return EXIT_FAILED
    return 0


def _positions_read(info: dict[str, Any]) -> str:
    """The import line's part on how a joint-positions file was read."""
    read = info.get("positions")
    if not read:
        return ""
    text = f", {read['read_as']}, fps from {read['fps_from']}"
    if read["samples_filled"]:
        text += f", {read['samples_filled']} missing joint samples interpolated"
    if read["absent_joints"]:
        text += f", missing in every frame (filled in): {', '.join(read['absent_joints'])}"
    if read["lowpass_hz"]:
        text += f", low-pass at {read['lowpass_hz']:g} Hz (jitter about {read['jitter_mm']:g} mm)"
    return text


def _events_and_treadmill(info: dict[str, Any]) -> str:
    """The import line's part on gait events and an in-place (treadmill) stance."""
    text = ""
    events = info.get("gait_events")
    if events:
        check = info.get("contacts", {}).get("events_check") or {}
        n = sum(e["kind"] in ("strike", "off") for e in events)
        text += f", {n} gait events"
        if check.get("worst_ms") is not None:
            text += f" (detected contacts within {check['worst_ms']:g} ms of them)"
    plates = info.get("force_plates")
    if plates:
        text += f", {len(plates)} force-plate contact{'s' * (len(plates) != 1)}"
        check = info.get("contacts", {}).get("plates_check") or {}
        if check.get("worst_ms") is not None:
            text += f" (contacts within {check['worst_ms']:g} ms of their measured edges)"
    centres = info.get("lab_joint_centres")
    if centres:
        joint, row = max(centres.items(), key=lambda kv: kv[1]["median_mm"])
        text += (f", {len(centres)} lab joint centres in the file: ours within "
                 f"{row['median_mm']:g} mm of them (median; farthest {joint})")
    belt = info.get("treadmill")
    if belt:
        text += (f"; in place on a treadmill-like belt at {belt['speed_mps']:g} m/s: "
                 + ("turned into root motion (--no-treadmill keeps it in place)"
                    if belt["converted"] else "kept in place (--no-treadmill)"))
    return text
