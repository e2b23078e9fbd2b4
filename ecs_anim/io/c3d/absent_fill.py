"""Absent body parts taken from a default motion (``--fill-absent-from``), in normalized form."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.motion.clip import NormalizedMotion


def load_default_motion(path: Path) -> NormalizedMotion:
    """The default motion ``--fill-absent-from`` names: a .nmo or a .bvh file."""
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.motion.clip import load_nmo

    if path.suffix.lower() == ".nmo":
        return load_nmo(path)
    if path.suffix.lower() == ".bvh":
        return import_bvh(path)
    raise EcsAnimError(f"--fill-absent-from {path}: expected a .nmo or .bvh motion")


#: Normalized fields of each body group: (field, side index or None).
GROUP_FIELDS: dict[str, tuple[tuple[str, int | None], ...]] = {
    "trunk": (("spine_points", None), ("thorax", None)),
    "head": (("neck_dir", None), ("head", None), ("head_top_dir", None)),
    **{f"arm_{s}": (("clavicle_dir", i), ("arm_frame", i), ("arm_fraction", i), ("hand_dir", i))
       for i, s in enumerate("lr")},
    **{f"leg_{s}": (("hip_dir", i), ("leg_frame", i), ("leg_fraction", i), ("foot_dir", i))
       for i, s in enumerate("lr")},
}


GROUP_SEGMENTS: dict[str, tuple[str, ...]] = {
    "trunk": ("spine_lower", "spine_middle", "spine_upper"), "head": ("neck", "head"),
    **{f"arm_{s}": (f"clavicle_{s}", f"upper_arm_{s}", f"forearm_{s}", f"hand_{s}") for s in "lr"},
    **{f"leg_{s}": (f"pelvis_{s}", f"thigh_{s}", f"shank_{s}", f"foot_{s}") for s in "lr"},
}


def fill_absent_from(motion: NormalizedMotion, default: NormalizedMotion, default_name: str,
                     thresholds: ContactThresholds = ContactThresholds()) -> NormalizedMotion:
    """Replace the absent body parts of ``motion`` (``info.absent``) by those of a default
    motion, frame by frame at the same time (the default loops), in normalized form: the parts
    are relative to their parent part, so e.g. a walk's arm swing rides on the captured trunk.
    The pelvis is never taken from the default. Foot contacts are detected again when legs were
    replaced. Returns a new motion; ``info.absent_fill`` names the default.
    """
    from ecs_anim.core.normalized import NormalizedPoses, decode
    from ecs_anim.core.skeleton import LENGTH_INDEX
    from ecs_anim.io.contacts import contact_constraints, detect_foot_contacts

    groups = [g for g in motion.info.get("absent", []) if g in GROUP_FIELDS]
    if not groups:
        return motion
    t = np.arange(motion.n_frames) / motion.fps
    index = np.round(t * default.fps).astype(int) % default.n_frames
    arrays = {k: v.copy() for k, v in motion.poses.arrays().items()}
    source = default.poses.arrays()
    for group in groups:
        for name, side in GROUP_FIELDS[group]:
            if side is None:
                arrays[name] = source[name][index].copy()
            else:
                arrays[name][:, side] = source[name][index, side]
        for segment in GROUP_SEGMENTS[group]:
            arrays["stretch"][:, LENGTH_INDEX[segment]] = 1.0
    poses = NormalizedPoses(**arrays)
    constraints, planted = motion.constraints, motion.planted
    if any(g.startswith("leg_") for g in groups):
        positions = decode(poses, motion.source_morphology.lengths, use_stretch=True).positions
        found = detect_foot_contacts(positions, motion.fps, thresholds)
        constraints = [c for c in motion.constraints if c.kind != "foot_contact"] + \
            contact_constraints(found.foot, motion.fps, thresholds)
        planted = {"heel": found.heel, "ball": found.ball, "foot": found.foot,
                   "on_ground": found.on_ground}
    info = dict(motion.info) | {"absent_fill": f"from {default_name}"}
    return NormalizedMotion(poses, motion.fps, motion.source_morphology, constraints, info,
                            planted, motion.capture_ground)
