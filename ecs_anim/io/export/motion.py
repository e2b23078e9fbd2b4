"""A normalized motion played on a body and written to one file: BVH, glTF (``.glb``) or joint
positions (``.npz``), chosen by the output's suffix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.files import atomic_output, output_problem
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import DecodedPose
from ecs_anim.io.export.bvh import bvh_text
from ecs_anim.io.export.gltf import glb_from_pose
from ecs_anim.io.export.npz import write_npz
from ecs_anim.io.export.onto import onto_rig_bytes, rig_of
from ecs_anim.io.export.positions import layout_positions, write_layout_positions
from ecs_anim.io.export.rig import Rig
from ecs_anim.io.export.skeleton import play_on, resolve_morphology
from ecs_anim.io.position_layouts import LAYOUTS, layout_named
from ecs_anim.motion.clip import NormalizedMotion


def export_motion(motion: NormalizedMotion, morphology_spec: str, out: str | Path,
                  force: bool = False, onto: str | Path | Rig | None = None,
                  rig_map: str | None = None, layout: str | None = None
                  ) -> tuple[Morphology, DecodedPose]:
    """Play ``motion`` on a body and write ``out`` (.bvh, .npz or .glb); an existing ``out``
    without ``force``, or a path that cannot be written, is an :class:`EcsAnimError` before any
    work. ``onto``: a rig (a .bvh, .glb or .gltf file, or a loaded :class:`Rig`; its joint map
    ``rig_map``, a preset or a map YAML, as import's ``--map``) whose body the motion is played
    on and whose hierarchy is written (:mod:`ecs_anim.io.export.onto`); ``morphology_spec``
    must then be ``"source"`` (the rig is the body). ``layout``: the joints of a research
    layout (:data:`~ecs_anim.io.position_layouts.LAYOUTS`) to a .npy or .npz
    (:mod:`ecs_anim.io.export.positions`)."""
    out = Path(out)
    suffix = out.suffix.lower()
    if layout is not None:
        chosen = layout_named(layout)
        if suffix not in (".npy", ".npz") or onto is not None:
            raise EcsAnimError(f"-o {out}: --layout {chosen.name} writes joint positions to a "
                               ".npy or .npz, not onto a rig")
    elif suffix == ".npy":
        raise EcsAnimError(f"-o {out}: a .npy holds one layout's joints; give --layout "
                           f"({', '.join(LAYOUTS)})")
    elif suffix not in (".bvh", ".npz", ".glb"):
        raise EcsAnimError(f"-o {out}: the output must end in .bvh, .npz or .glb "
                           "(.npy with --layout)")
    problem = output_problem(out, force)
    if problem is not None:
        raise EcsAnimError(problem)
    rig = None
    if onto is not None:
        if morphology_spec != "source":
            raise EcsAnimError(f"--morphology {morphology_spec} and --onto {getattr(onto, 'path', onto)}: the rig is the "
                               "body the motion is played on; give one of them")
        rig = rig_of(onto, rig_map)
        morph, is_source = rig.morphology, False
    else:
        morph, is_source = resolve_morphology(morphology_spec, motion)
    # BVH and glTF bones are rigid, so they get the rigid body even on the source morphology;
    # the .npz on the source carries the measured stretch and reproduces the source exactly.
    pose = play_on(motion, morph, is_source and suffix in (".npz", ".npy"))
    if not np.all(np.isfinite(pose.positions)):
        raise EcsAnimError(f"{out}: the decoded motion holds non-finite positions (bug); nothing written")
    with atomic_output(out, force) as f:
        if layout is not None:
            write_layout_positions(f, layout_positions(pose, morph.leg_length, chosen),
                                   chosen, motion.fps, npz=suffix == ".npz")
        elif rig is not None:
            f.write(onto_rig_bytes(rig, pose, suffix[1:], motion.fps, motion.contacts()))
        elif suffix == ".bvh":
            f.write(bvh_text(pose, morph, motion.fps).encode("utf-8"))
        elif suffix == ".glb":
            f.write(glb_from_pose(pose, morph, motion.fps))
        else:
            write_npz(f, pose.positions, motion.fps, motion.contacts())
    return morph, pose
