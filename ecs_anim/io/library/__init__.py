"""The project's own motion library: clips authored from footprints and keyframes (no captured
data), shipped as ``scenarios/motions/*.bvh``."""

from ecs_anim.io.library.shipped import (
    MOTIONS_DIR,
    all_generators,
    authored_bvh_text,
    authored_poses,
    shipped_motion_paths,
)

__all__ = ["MOTIONS_DIR", "all_generators", "authored_bvh_text", "authored_poses",
           "shipped_motion_paths"]
