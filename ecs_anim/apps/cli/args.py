"""The command line's argument types, its one-line error and JSON helpers and the exit status of
a failed command, shared by every command (``batch`` too)."""

from __future__ import annotations

import argparse
import math
from typing import Any

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.io.importing import FrameRange
from ecs_anim.motion.clip import FACINGS

#: The exit status of a command that failed (a user error, or some of its files).
EXIT_FAILED = 1

#: The longest error line printed: a last guard (messages cut their own lists with ``listed``).
MAX_ERROR_CHARS = 300


def add_rig_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """``--onto RIG`` (``what`` says what goes onto the rig) and ``--map``, alike in every
    command that writes onto a user's rig (docs/export.md)."""
    parser.add_argument("--onto", metavar="RIG.bvh|RIG.glb|RIG.fbx",
                        help=f"{what} retargeted onto this rig's body and written in its own "
                             "hierarchy, names and rest pose (docs/export.md)")
    parser.add_argument("--map", metavar="PRESET|FILE.yaml",
                        help="how the --onto rig's joints are our body parts, as import's --map "
                             "(default: detected)")


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


def facing(text: str) -> float:
    """argparse type of ``--face``: ``+x``, ``-x``, ``+y``, ``-y`` or degrees; radians."""
    if text.strip().lower() in FACINGS:
        return FACINGS[text.strip().lower()]
    try:
        degrees = float(text)
    except ValueError:
        degrees = math.nan
    if not (math.isfinite(degrees) and abs(degrees) <= 360.0):
        raise argparse.ArgumentTypeError(f"--face {text!r}: expected +x, -x, +y, -y or degrees "
                                         "from -360 to 360")
    return math.radians(degrees)


def up_axis(text: str) -> str:
    """argparse type of ``--up``: ``x``, ``y``, ``z`` or a negative one (``-y``: the file is
    upside down, Y pointing down), :func:`~ecs_anim.io.importing.up_axis`."""
    from ecs_anim.io.importing import up_axis as parse_up
    try:
        return parse_up(text)
    except EcsAnimError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--up {text}: ")) from None


#: Flags whose value may be a negative axis (``--up -y``, ``--face -x``): argparse reads a word
#: starting with "-" as a flag, so :func:`joined_axis_values` joins these to their flag.
AXIS_FLAGS = ("--up", "--face")
AXIS_WORDS = frozenset(f"{sign}{axis}" for sign in "-+" for axis in "xyzXYZ")


def joined_axis_values(argv: list[str]) -> list[str]:
    """``argv`` with ``--up -y`` written ``--up=-y`` (the same for :data:`AXIS_FLAGS`), so that
    argparse takes a negative axis as the flag's value, not as a flag of its own."""
    out: list[str] = []
    k = 0
    while k < len(argv):
        if argv[k] in AXIS_FLAGS and k + 1 < len(argv) and argv[k + 1] in AXIS_WORDS:
            out.append(f"{argv[k]}={argv[k + 1]}")
            k += 2
        else:
            out.append(argv[k])
            k += 1
    return out


def frame_range(text: str) -> FrameRange:
    """argparse type of ``--trim``: :meth:`FrameRange.parse`, its error as argparse's."""
    try:
        return FrameRange.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def length_unit(text: str) -> str:
    """argparse type of ``--unit``: a unit name or metres per file unit
    (:func:`~ecs_anim.io.importing.unit_scale`), kept as text."""
    from ecs_anim.io.importing import unit_scale
    try:
        unit_scale(text)
    except EcsAnimError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--unit {text}: ")) from None
    return text


def positive_int(text: str) -> int:
    """argparse type: a whole number >= 1."""
    if not text.isascii() or not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return int(text)


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None: strict JSON has no NaN or
    Infinity, and a report must load in any JSON reader."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def error_line(exc: Exception) -> str:
    """What the user sees of an error: one line of at most :data:`MAX_ERROR_CHARS` characters;
    a system error names its file (``path: No such file or directory``)."""
    if isinstance(exc, OSError) and not isinstance(exc, FileExistsError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    else:
        text = str(exc)
    text = " ".join(text.splitlines())
    return text if len(text) <= MAX_ERROR_CHARS else text[:MAX_ERROR_CHARS - 3] + "..."
