"""Writing a played motion for other tools: BVH, binary glTF (``.glb``) and joint positions
(``.npz``), on the export skeleton (the canonical joints as a rigid hierarchy)."""

from ecs_anim.io.export.bvh import bvh_from_rotations, bvh_text
from ecs_anim.io.export.gltf import glb_bytes, glb_from_pose
from ecs_anim.io.export.motion import export_motion, write_npz
from ecs_anim.io.export.skeleton import EXPORT_NAMES, local_rotations, play_on, resolve_morphology

__all__ = [
    "EXPORT_NAMES",
    "bvh_from_rotations",
    "bvh_text",
    "export_motion",
    "glb_bytes",
    "glb_from_pose",
    "local_rotations",
    "play_on",
    "resolve_morphology",
    "write_npz",
]
