"""Writing a played motion for other tools: BVH, binary glTF (``.glb``) and joint positions
(``.npz``), on the export skeleton (the canonical joints as a rigid hierarchy)."""

from ecs_anim.io.export.bvh import bvh_from_rotations, bvh_text
from ecs_anim.io.export.gltf import glb_bytes, glb_from_pose
from ecs_anim.io.export.motion import export_motion
from ecs_anim.io.export.npz import write_npz
from ecs_anim.io.export.onto import (
    bvh_onto_rig,
    glb_onto_rig,
    onto_rig_bytes,
    recorded_on_rig,
    rig_of,
)
from ecs_anim.io.export.rig import Rig, RigPose, load_rig, rig_pose
from ecs_anim.io.export.skeleton import EXPORT_NAMES, local_rotations, play_on, resolve_morphology

__all__ = [
    "EXPORT_NAMES",
    "Rig",
    "RigPose",
    "bvh_from_rotations",
    "bvh_onto_rig",
    "bvh_text",
    "export_motion",
    "glb_bytes",
    "glb_from_pose",
    "glb_onto_rig",
    "load_rig",
    "local_rotations",
    "onto_rig_bytes",
    "play_on",
    "recorded_on_rig",
    "resolve_morphology",
    "rig_of",
    "rig_pose",
    "write_npz",
]
