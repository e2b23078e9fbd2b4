"""``ecs-anim info``: what a normalized motion holds, for one file or a table of several."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ecs_anim.apps.cli.args import EXIT_FAILED
from ecs_anim.core.errors import EcsAnimError, listed
from ecs_anim.motion.clip import NormalizedMotion


def played_on_own_body(motion: NormalizedMotion) -> dict[str, float]:
    """How the clip's planted feet fare played once through ``run``'s pipeline on its own
    (source) body on flat ground: the metrics of ``run``'s table (mm), so a clip whose planted
    soles float or slide is seen before it is used."""
    from ecs_anim.core.ground import Plane
    from ecs_anim.scenario import clip_scenario, measured_run

    character = measured_run(clip_scenario(motion, motion.source_morphology,
                                           Plane()))["characters"][0]
    return {"floating_mm_max": character["floating_mm_max"],
            "penetration_mm_max": character["ground_penetration_mm_max"],
            "sliding_mm_per_frame_max": character["foot_sliding_mm_per_frame"]["max"]}


def reach_on_own_body(motion: NormalizedMotion) -> list[dict[str, object]]:
    """Whether each constraint stored with the clip (not its foot contacts) can reach its
    target on the clip's own body (``Simulation.feasibility``; none stored: empty)."""
    from ecs_anim.core.ground import Plane
    from ecs_anim.scenario import build_simulation, clip_scenario

    if all(c.kind == "foot_contact" for c in motion.constraints):
        return []
    with build_simulation(clip_scenario(motion, motion.source_morphology, Plane())) as sim:
        return [estimate.as_dict() for estimate in sim.feasibility()]


def motion_summary(path: str) -> dict[str, object]:
    """What the .nmo file at ``path`` holds, as JSON-able data (``info --json``), with how its
    planted feet fare played on its own body (:func:`played_on_own_body`)."""
    from ecs_anim.motion.clip import facing_and_travel, load_nmo

    motion = load_nmo(path)
    contacts = motion.contacts()
    return {
        "file": path,
        "frames": motion.n_frames,
        "fps": motion.fps,
        "duration_s": round(motion.duration_s, 4),
        "root": facing_and_travel(motion),
        "source_morphology": motion.source_morphology.to_dict()
        | {"stature_m": round(motion.source_morphology.stature, 4)},
        "contacts": {
            "left_fraction": float(contacts[:, 0].mean()),
            "right_fraction": float(contacts[:, 1].mean()),
            "constraints": [
                {"name": c.name, "start_s": round(c.activation.start_s, 4),
                 "stop_s": round(c.activation.stop_s, 4)}
                for c in motion.constraints if c.kind == "foot_contact"
            ],
        },
        "other_constraints": [c.to_dict() for c in motion.constraints if c.kind != "foot_contact"],
        "feasibility": reach_on_own_body(motion),
        "played_on_own_body": played_on_own_body(motion),
        "info": motion.info,
    }


def _info_files(given: list[str]) -> list[str]:
    """The .nmo files named, a folder standing for the .nmo files in it (sorted)."""
    files: list[str] = []
    for name in given:
        if Path(name).is_dir():
            found = sorted(str(p) for p in Path(name).glob("*.nmo"))
            if not found:
                raise EcsAnimError(f"{name}: a folder with no .nmo file (import clips first: "
                                   f"ecs-anim import CLIP.bvh -o {name})")
            files.extend(found)
        else:
            files.append(name)
    return files


def cmd_info(args: argparse.Namespace) -> int:
    """``ecs-anim info``: one file in detail, or several (a folder) as a table."""
    files = _info_files(args.file)
    if len(files) > 1 or Path(args.file[0]).is_dir():
        return _info_table(files, args.json)
    summary = motion_summary(files[0])
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    m = summary["source_morphology"]
    c = summary["contacts"]
    info = summary["info"]
    root = summary["root"]
    assert isinstance(m, dict) and isinstance(c, dict) and isinstance(info, dict) and isinstance(root, dict)
    print(f"{files[0]}")
    print(f"  frames     {summary['frames']} at {summary['fps']:g} fps ({summary['duration_s']} s)")
    print(f"  facing     {root['facing_deg']:g} deg from +x at the first frame; the root travels "
          f"{root['straight_m']:g} m towards {root['direction_deg']:g} deg ({root['path_m']:g} m "
          "along its path)")
    print(f"  source     {info.get('source', '?')} ({info.get('joint_map', '?')}, unit "
          f"{info.get('unit', '?')})")
    print(f"  body       stature {m['stature_m']:.3f} m, mass {m['mass_kg']:.1f} kg, "
          f"leg (thigh+shank) {0.5 * (m['lengths_m']['thigh_l'] + m['lengths_m']['shank_l'] + m['lengths_m']['thigh_r'] + m['lengths_m']['shank_r']):.3f} m")
    print(f"  contacts   left {c['left_fraction']:.0%} right {c['right_fraction']:.0%} of frames, "
          f"{len(c['constraints'])} contact intervals")
    played = summary["played_on_own_body"]
    assert isinstance(played, dict)
    print(f"  played     on its own body, flat ground: planted feet floating "
          f"{played['floating_mm_max']:.1f} mm, penetration {played['penetration_mm_max']:.1f} mm,"
          f" sliding {played['sliding_mm_per_frame_max']:.1f} mm per frame (max)")
    for estimate in summary["feasibility"]:  # type: ignore[attr-defined]
        print(f"  reach      {estimate['line']}")
    filled = info.get("filled_in")
    if filled:
        print(f"  filled in  {', '.join(map(str, filled)) if isinstance(filled, list) else filled}")
    absent = info.get("absent")
    if absent and isinstance(absent, list):
        print(f"  absent     {', '.join(map(str, absent))} (no markers: {info.get('absent_fill')})")
    for key, what in (("root_frames_trimmed", "trimmed    frames {} of the file"),
                      ("root_frames_repaired", "repaired   frames {}")):
        spans = info.get(key)
        if spans and isinstance(spans, list):
            shown = ", ".join(f"{a}-{b}" for a, b in spans)
            print(f"  {what.format(shown)} (the pelvis markers could not place the pelvis)")
    for line in info.get("parts_frames_trimmed") or []:
        print(f"  trimmed    {line}")
    if info.get("first_file_frame"):
        print(f"  starts at  frame {info['first_file_frame']} of the file (--trim, a rest pose "
              "dropped, or frames the markers could not place)")
    if info.get("rest_frames_dropped"):
        print(f"  {info['rest_frames_dropped']}")
    for why in (info.get("parts_not_computed") or {}).values():
        print(f"  {why}")
    contacts_info = info.get("contacts") or {}
    if contacts_info:
        print(f"  contacts   {contacts_info.get('method', 'detected')}"
              + (f", still under {'/'.join(f'{v:g}' for v in contacts_info['speed_threshold_mps'])}"
                 " m/s (heel/ball)" if contacts_info.get("speed_threshold_mps") else ""))
    for event in info.get("gait_events") or []:
        what = f"{event['side'].upper()} {'foot strike' if event['kind'] == 'strike' else 'foot off'}" \
            if event.get("kind") else f"{event['label'] or '-'} ({event['context'] or '-'})"
        print(f"  event      {event['time_s']:8.3f} s  {what}")
    check = contacts_info.get("events_check")
    if check:
        print(f"  events     detected contacts within {check['worst_ms']:g} ms of the gait events"
              if check.get("worst_ms") is not None else
              "  events     some gait event has no detected contact edge")
    for plate in info.get("force_plates") or []:
        edges = [name for name, key in (("touch-down", "touch_down"), ("lift-off", "lift_off"))
                 if plate[key]]
        foot = f"{plate['side'].upper()} foot" if plate["side"] else plate.get("why", "")
        print(f"  plate {plate['plate']:<4d} {plate['on_s']:8.3f}-{plate['off_s']:.3f} s  {foot}"
              + (f" (measured {' and '.join(edges)})" if edges else " (no edge measured)"))
    for note in info.get("force_plate_notes") or []:
        print(f"  plates     {note}")
    check = contacts_info.get("plates_check")
    if check:
        print(f"  plates     contacts within {check['worst_ms']:g} ms of the plates' touch-downs and"
              " lift-offs" if check.get("worst_ms") is not None else
              "  plates     some measured plate edge has no contact edge")
    belt = info.get("treadmill")
    if belt:
        print(f"  treadmill  in place, belt {belt['speed_mps']:g} m/s: "
              + ("turned into root motion" if belt["converted"] else "kept in place"))
    centres = info.get("lab_joint_centres")
    if centres:
        for joint, row in centres.items():
            print(f"  lab centre {joint:<8} ours {row['median_mm']:.0f} mm from {row['label']} "
                  f"(median; 95th percentile {row['p95_mm']:.0f} mm)")
    return 0


def _info_table(files: list[str], as_json: bool) -> int:
    """``info`` on several files: one row each; a file that cannot be read is a row saying why,
    and the others go on (exit status 1 if any failed)."""
    rows: list[dict[str, Any]] = []
    for name in files:
        try:
            rows.append(motion_summary(name))
        except EcsAnimError as exc:
            rows.append({"file": name, "error": str(exc)})
    failed = sum("error" in r for r in rows)
    if as_json:
        print(json.dumps(rows, indent=2))
        return EXIT_FAILED if failed else 0
    print(f"{'file':<28} {'frames':>6} {'fps':>5} {'s':>6} {'facing':>7} {'travel m':>8} "
          f"{'L %':>4} {'R %':>4} {'float':>6} {'pen':>6} {'slide':>6}  parts filled in or absent")
    for r in rows:
        label = Path(str(r["file"])).name
        label = label if len(label) <= 28 else label[:25] + "..."
        if "error" in r:
            print(f"{label:<28} error: {r['error']}")
            continue
        c, root, info, played = r["contacts"], r["root"], r["info"], r["played_on_own_body"]
        parts = list(info.get("absent") or []) + [f"{j} (filled)" for j in info.get("filled_in") or []]
        print(f"{label:<28} {r['frames']:>6} {r['fps']:>5g} {r['duration_s']:>6.2f} "
              f"{root['facing_deg']:>7g} {root['straight_m']:>8.2f} {c['left_fraction']:>4.0%} "
              f"{c['right_fraction']:>4.0%} {played['floating_mm_max']:>6.1f} "
              f"{played['penetration_mm_max']:>6.1f} {played['sliding_mm_per_frame_max']:>6.1f}  "
              f"{listed(parts, 4) or '-'}")
    if failed:
        print(f"{failed} of {len(rows)} file(s) could not be read", file=sys.stderr)
        return EXIT_FAILED
    return 0
