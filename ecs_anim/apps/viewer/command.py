"""``ecs-anim view``: the command-line entry of the viewer (kept here so cli.py only wires it)."""

from __future__ import annotations

import argparse
import math
import re

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


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", metavar="SCENARIO.yaml")
    p.add_argument("--screenshot", metavar="OUT.png",
                   help="render one frame without a screen (headless EGL), write a PNG and exit")
    p.add_argument("--at", type=seconds, default=0.0, metavar="SECONDS",
                   help="with --screenshot: the simulation time of the frame (default 0)")
    p.add_argument("--size", type=window_size, default=(1280, 720), metavar="WxH",
                   help="window or image size in pixels (default 1280x720)")
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
    width, height = args.size
    if args.screenshot is None:
        if args.at or args.force:
            raise EcsAnimError("--at and --force go with --screenshot OUT.png")
        from ecs_anim.apps.viewer.window import run_viewer

        run_viewer(scenario, width, height, show_targets=not args.no_targets,
                   show_com=not args.no_com)
        return 0
    problem = input_problem(args.screenshot, scenario.input_files)
    if problem is not None:
        raise EcsAnimError(f"--screenshot {problem}")
    if args.at > scenario.duration_s:
        raise EcsAnimError(f"--at {args.at:g} is after the scenario's end ({scenario.duration_s:g} s)")
    from ecs_anim.apps.viewer.screenshot import write_screenshot

    shot = write_screenshot(scenario, args.screenshot, args.at, width, height, args.force,
                            show_targets=not args.no_targets, show_com=not args.no_com)
    print(f"wrote {args.screenshot}: {width}x{height}, t = {shot.frame.time_s:.3f} s, "
          f"{shot.frame.n_characters} characters")
    return 0
