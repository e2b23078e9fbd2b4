"""Exported files as Blender reads them: run by Blender's Python (the ``bpy`` module, in its own
environment), not ours, by ``tests/io/export/test_blender_reads_exports.py``.

    BLENDER_PYTHON tests/support/blender_positions.py JOBS.json

``JOBS.json`` is a list of jobs, ``{"file": "X.bvh", "out": "X.npz", "bvh_unit": metres per
file unit, "bvh_up": "y" or "z"}`` or ``{"file": "X.glb", "out": "X.npz", "fps": samples per
second}``. Each file is imported into an empty scene by Blender's own importer, the scene is
stepped through every frame of its one action (``scene.frame_set``), and ``out`` gets ``names``
(each bone's name, then ``<bone>.end`` for each bone without children: its tail, where a BVH's
End Site is) and ``positions`` (frames, names, 3): their world places (``armature.matrix_world
@ pose_bone.head``, or ``.tail``), metres, Blender's Z up. Nothing of ecs_anim is imported here.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import bpy  # type: ignore[import-not-found]  # only in Blender's Python, which runs this
import numpy as np

#: The BVH importer's ``axis_forward`` and ``axis_up`` for a file's up axis, chosen so that
#: Blender's world is the file's turned as our readers turn it: a Y-up file's (x, y, z) becomes
#: (x, -z, y) (the importer's defaults), a Z-up file's stays as it is (Blender's own axes).
BVH_AXES = {"y": ("-Z", "Y"), "z": ("Y", "Z")}


def import_bvh(path: Path, unit_m: float, up: str) -> None:
    """Import a BVH with one Blender frame per BVH frame, the first at Blender frame 1."""
    forward, upward = BVH_AXES[up]
    # global_scale: the file's unit in metres, so that Blender's world is in metres as ours.
    # use_fps_scale=False: BVH frame k is keyed on Blender frame frame_start + k exactly, where
    # scaling to the scene's rate would put keys between Blender's frames, which frame_set would
    # interpolate. update_scene_fps=True gives the scene the file's rate, as a user would, and
    # turns the scaling off by itself too. frame_start=1, the default.
    bpy.ops.import_anim.bvh(filepath=str(path), global_scale=unit_m, axis_forward=forward,
                            axis_up=upward, rotate_mode="NATIVE", use_fps_scale=False,
                            update_scene_fps=True, frame_start=1)


def import_glb(path: Path, fps: int) -> None:
    """Import a GLB with the importer's defaults (Y up turned to Blender's Z up: (x, y, z) ->
    (x, -z, y); its bone axes guessed, which moves no bone's head). The importer keys a sample
    at t seconds on Blender frame t * (the scene's rate), so the scene's rate is first set to
    the file's ``fps`` (samples per second, a whole number): sample k lands on frame k. Its
    ``fps_base`` stays 1: the importer multiplies the rate by it rather than divides."""
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = fps, 1.0
    bpy.ops.import_scene.gltf(filepath=str(path))


def sampled_positions(armature: bpy.types.Object) -> tuple[list[str], np.ndarray]:
    """(names, (frames, names, 3) world places in metres) over the armature's action's frames."""
    scene = bpy.context.scene
    action = armature.animation_data.action
    first, last = (round(f) for f in action.frame_range)
    bones = list(armature.pose.bones)
    leaves = [b for b in bones if not b.children]
    names = [b.name for b in bones] + [f"{b.name}.end" for b in leaves]
    positions = np.empty((last - first + 1, len(names), 3))
    for row, frame in enumerate(range(first, last + 1)):
        scene.frame_set(frame)
        to_world = armature.matrix_world
        places = [to_world @ b.head for b in bones] + [to_world @ b.tail for b in leaves]
        positions[row] = np.array([tuple(p) for p in places])
    return names, positions


def main(jobs_path: str) -> None:
    for job in json.loads(Path(jobs_path).read_text()):
        path = Path(job["file"])
        bpy.ops.wm.read_factory_settings(use_empty=True)
        if path.suffix == ".bvh":
            import_bvh(path, job["bvh_unit"], job["bvh_up"])
        else:
            import_glb(path, job["fps"])
        (armature,) = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
        names, positions = sampled_positions(armature)
        np.savez(job["out"], names=np.array(names), positions=positions)


if __name__ == "__main__":
    main(sys.argv[-1])
