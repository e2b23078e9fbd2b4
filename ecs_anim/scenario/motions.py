"""A scenario's ``motions:``: clips read from BVH, C3D or ``.nmo`` files, each once, and the body
parts a capture lacks filled from another clip."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from yaml import Node

from ecs_anim.components import QueuedClip
from ecs_anim.core.errors import (
    EcsAnimError,
    did_you_mean,
)
from ecs_anim.motion.clip import NormalizedMotion, load_nmo
from ecs_anim.scenario.reader import Fails, YamlReader


def load_motion(r: YamlReader, node: Node, where: str, base_dir: Path,
                 read: dict[Path, NormalizedMotion]) -> NormalizedMotion:
    """The motion a file holds; ``read`` (resolved path -> motion) keeps each file read once,
    however many names it is given (or an alias repeats)."""
    rel = r.string(node, where)
    path = (base_dir / rel) if not Path(rel).is_absolute() else Path(rel)
    if path.is_dir():
        raise r.fail(node, where, f"{rel!r} is a folder, not a motion file (looked at {path})")
    if not path.is_file():
        raise r.fail(node, where, f"motion file {rel!r} not found (looked at {path})")
    if path.resolve() not in read:
        read[path.resolve()] = read_motion(r, node, where, path, rel)
    return read[path.resolve()]


def read_motion(r: Fails, node: Node | None, where: str, path: Path,
                 rel: str) -> NormalizedMotion:
    from ecs_anim.io.acclaim import import_amc
    from ecs_anim.io.c3d.importing import import_c3d
    from ecs_anim.io.fbx import import_fbx
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.io.trc import import_trc

    try:
        if path.suffix.lower() == ".nmo":
            return load_nmo(path)
        if path.suffix.lower() == ".bvh":
            return import_bvh(path)
        if path.suffix.lower() == ".c3d":
            return import_c3d(path)
        if path.suffix.lower() == ".fbx":
            return import_fbx(path)  # its first take
        if path.suffix.lower() == ".trc":
            return import_trc(path)
        if path.suffix.lower() == ".amc":
            return import_amc(path)  # the .asf beside it, at CMU's 120 fps
    except EcsAnimError as exc:
        raise r.fail(node, where, f"cannot load motion: {exc}") from None
    raise r.fail(node, where, f"expected a .bvh, .c3d, .fbx, .trc, .amc or .nmo file, found "
                              f"{rel!r}")


def fill_absent(r: YamlReader, motions: dict[str, NormalizedMotion], name: str, node: Node) -> None:
    """``motions.NAME.absent_from: OTHER``: the body parts NAME's capture lacks (a lower-body
    C3D's trunk, head and arms) are played from motion OTHER, looped, instead of a neutral
    pose."""
    from ecs_anim.io.c3d.absent_fill import fill_absent_from

    where = f"motions.{name}.absent_from"
    other = r.string(node, where)
    if other == name or other not in motions:
        hint = did_you_mean(other, [m for m in motions if m != name])
        raise r.fail(node, where, f"no other motion named {other!r}{hint}")
    if not motions[name].info.get("absent"):
        raise r.fail(node, where, f"{name!r} has every body part: nothing to take from {other!r}")
    motions[name] = fill_absent_from(motions[name], motions[other], other)


def motion_name(r: YamlReader, n: Node, w: str, motions: dict[str, NormalizedMotion]) -> str:
    """The name of one of ``motions`` at node ``n`` (``w`` its place in the file), or a
    ``file:line:`` error with "did you mean"."""
    c = r.string(n, w)
    if c not in motions:
        hint = did_you_mean(c, list(motions))
        raise r.fail(n, w, f"unknown motion {c!r}{hint} (motions: {', '.join(motions)})")
    return c


def queued_clips(r: YamlReader, node: Node, where: str, clip: Callable[[Node, str], str],
                  most: int) -> tuple[QueuedClip, ...]:
    """A ``then:`` list of clips to play next (at most ``most``); ``clip`` reads a motion name."""
    queued = r.sequence(node, where)
    if len(queued) > most:
        raise r.fail(node, where, f"at most {most} clips can be queued")
    queue = []
    for j, q in enumerate(queued):
        qw = f"{where}[{j}]"
        qk = r.mapping(q, qw, {"motion": True, "crossfade_s": False, "loop": False})
        queue.append(QueuedClip(
            clip(qk["motion"], f"{qw}.motion"),
            r.number(qk["crossfade_s"], f"{qw}.crossfade_s", 0.0, 10.0, "s") if "crossfade_s" in qk else 0.3,
            r.boolean(qk["loop"], f"{qw}.loop") if "loop" in qk else False))
    return tuple(queue)
