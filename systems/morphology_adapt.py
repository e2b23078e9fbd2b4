"""MorphologyAdapt: the normalized poses on each character's own body (paper §6, eq. 2).

Rows: characters with a Morphology. A body replaced while playing (``Simulation.set_body``)
is taken in on the next tick, before any system decodes the pose on it
(:func:`ecs_anim.runtime.body_change.adopt_bodies`), or blended into over ``blend_s`` tick by tick
(:func:`ecs_anim.runtime.body_change.blend_bodies`).

Reads: store.poses, store.lengths; on a body change the Morphology (and BodyBlend) components, segment_mass_kg,
segment_com_fraction, placement_*, fade_placement_*, posture (whether the character has played).
Writes: on a body change lengths, segment_mass_kg, segment_com_fraction, placement_xy,
fade_placement_xy (it stays where it stands), the root of poses, locked (its feet re-plant; while
blending, footprints stay: they lie on the ground whatever the body).

The scaling itself (eq. 2: segment lengths, the root by the leg length) is not stored: the
systems that need the pose on each body decode it in their own kernels, each what it reads
(GroundAdapt the pelvis and legs, ConstraintSolve and PostureConvert the whole body), so that
no pass over every character decodes a pose only to hand it on.
"""

from __future__ import annotations

from ecs_anim.components import Morphology
from ecs_anim.runtime.body_change import adopt_bodies, blend_bodies
from ecs_anim.runtime.system_base import System


class MorphologyAdapt(System):
    query = (Morphology,)
    on_structure_change = (adopt_bodies,)
    reads = ("poses", "lengths", "segment_mass_kg", "segment_com_fraction", "placement_xy",
             "placement_heading", "fade_placement_xy", "fade_placement_heading", "posture")
    writes = ("lengths", "segment_mass_kg", "segment_com_fraction", "placement_xy",
              "fade_placement_xy", "poses", "locked")

    def run(self, dt: float) -> None:
        blend_bodies(self.sim)  # a new body itself is taken in by ``on_structure_change``
