"""``ecs-anim view``: the command-line entry of the viewer (kept here so cli.py only wires it)."""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
from collections.abc import Callable

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.files import input_problem, output_problem


def window_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` in pixels, e.g. ``1280x720``."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels (e.g. 1280x720), got {text!r}")
    w, h = int(match.group(1)), int(match.group(2))
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"width and height must be 16-8192 pixels, got {w}x{h}")
    return w, h


def seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a time in seconds, got {text!r}") from None
    if not (math.isfinite(value) and 0 <= value <= 86400):
        raise argparse.ArgumentTypeError(f"expected a time from 0 to 86400 s, got {text!r}")
    return value


def degrees(low: float, high: float) -> Callable[[str], float]:
    """An argparse type: an angle in degrees from ``low`` to ``high``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected degrees, got {text!r}") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f"expected {low:g} to {high:g} degrees, got {text!r}")
        return value

    return parse


def only_names(text: str | None, names: list[str]) -> frozenset[str] | None:
    """``--only``'s comma-separated names, each checked against the scenario's characters."""
    if text is None:
        return None
    wanted = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in wanted if n not in names]
    if unknown or not wanted:
        raise EcsAnimError(f"--only {text!r}: no character named {', '.join(unknown) or '(none given)'}; "
                           f"the scenario has {', '.join(names)}")
    return frozenset(wanted)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", metavar="SCENARIO.yaml")
    p.add_argument("--screenshot", metavar="OUT.png",
                   help="render one frame without a screen (headless EGL), write a PNG and exit")
    p.add_argument("--at", type=seconds, default=0.0, metavar="SECONDS",
                   help="with --screenshot: the simulation time of the frame (default 0)")
    p.add_argument("--size", type=window_size, default=(1280, 720), metavar="WxH",
                   help="window or image size in pixels (default 1280x720)")
    p.add_argument("--yaw-deg", type=degrees(-360, 360), metavar="DEG",
                   help="the eye's direction about Z from +x (overrides the scenario's camera)")
    p.add_argument("--pitch-deg", type=degrees(-89, 89), metavar="DEG",
                   help="the eye's elevation (overrides the scenario's camera)")
    p.add_argument("--only", metavar="NAME,NAME",
                   help="with --screenshot: draw and frame only these characters (all are "
                        "simulated)")
    p.add_argument("--no-targets", action="store_true", help="hide constraint targets")
    p.add_argument("--no-com", action="store_true", help="hide the centres of mass")
    p.add_argument("--force", action="store_true", help="overwrite an existing screenshot")


def cmd_view(args: argparse.Namespace) -> int:
    from ecs_anim.scenario import load_scenario

    if args.screenshot is not None and not str(args.screenshot).lower().endswith(".png"):
        raise EcsAnimError(f"--screenshot {args.screenshot}: screenshots are PNG files: name it .png")
    if args.screenshot is not None:
        problem = output_problem(args.screenshot, args.force)
        if problem is not None:
            raise EcsAnimError(f"--screenshot {problem}")
    scenario = load_scenario(args.scenario)
    looks = {key: value for key, value in (("yaw_deg", args.yaw_deg), ("pitch_deg", args.pitch_deg))
             if value is not None}
    if looks:
        scenario = dataclasses.replace(scenario, camera={**scenario.camera, **looks})
    width, height = args.size
    if args.screenshot is None:
        if args.at or args.force or args.only is not None:
            raise EcsAnimError("--at, --only and --force go with --screenshot OUT.png")
        from ecs_anim.apps.viewer.window import run_viewer

        run_viewer(scenario, width, height, show_targets=not args.no_targets,
                   show_com=not args.no_com)
        return 0
    problem = input_problem(args.screenshot, scenario.input_files)
    if problem is not None:
        raise EcsAnimError(f"--screenshot {problem}")
    if args.at > scenario.duration_s:
        raise EcsAnimError(f"--at {args.at:g} is after the scenario's end ({scenario.duration_s:g} s)")
    only = only_names(args.only, [c.name for c in scenario.characters])
    from ecs_anim.apps.viewer.screenshot import write_screenshot

    shot = write_screenshot(scenario, args.screenshot, args.at, width, height, args.force,
                            show_targets=not args.no_targets, show_com=not args.no_com,
                            only=only)
    print(f"wrote {args.screenshot}: {width}x{height}, t = {shot.frame.time_s:.3f} s, "
          f"{shot.frame.n_characters} characters")
    return 0
