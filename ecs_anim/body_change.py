"""A body replaced while the character plays (paper §6): MorphologyAdapt takes it in.

``Simulation.set_body`` only replaces the character's Morphology component (a structural
change). On the next tick, before decoding, MorphologyAdapt runs :func:`adopt_bodies`: the rows
whose component differs from the store get the new segment lengths and masses, and because the
root path is stored in leg lengths (a new leg length would move the character along its path),
their placement is shifted so the character stays where it is; its feet re-plant.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .morphology import DE_LEVA_1996, MASS_SEGMENTS, Morphology, leg_length
from .playback import rotate_xy

if TYPE_CHECKING:
    from .simulation import Simulation


def mass_tables(bodies: list[Morphology]) -> tuple[np.ndarray, np.ndarray]:
    """Each body's de Leva segment masses (kg) and centre-of-mass fractions, (k, segments)
    each: :func:`ecs_anim.morphology.segment_mass_table` for many bodies at once."""
    table = {sex: np.array([rows[s[3]] for s in MASS_SEGMENTS]) for sex, rows in DE_LEVA_1996.items()}
    per_body = np.array([table[b.sex] for b in bodies]).reshape(len(bodies), len(MASS_SEGMENTS), 2)
    mass_kg = np.array([b.mass_kg for b in bodies], dtype=np.float64)
    return per_body[..., 0] * mass_kg[:, None], per_body[..., 1].copy()


def adopt_bodies(sim: Simulation) -> None:
    """Take replaced Morphology components into the store (between MotionPlayback and the
    decode of MorphologyAdapt). Writes store.lengths, segment_mass_kg, segment_com_fraction,
    placement_xy, fade_placement_xy, the root of this tick's poses, and locked (released)."""
    st = sim.store
    rows, bodies = sim.rows_and_components(Morphology)
    if rows.size == 0:
        return
    lengths = np.array([b.lengths for b in bodies])
    masses, fractions = mass_tables(bodies)
    changed = (np.any(lengths != st.lengths[rows], axis=1)
               | np.any(masses != st.segment_mass_kg[rows], axis=1)
               | np.any(fractions != st.segment_com_fraction[rows], axis=1))
    if not changed.any():
        return
    r = rows[changed]
    old_leg = leg_length(st.lengths[r])[:, None]
    new_leg = leg_length(lengths[changed])[:, None]
    # Only a character that has played keeps its place; one replaced before its first tick
    # starts from its placement on the new body.
    played = np.zeros(r.shape, bool) if st.posture is None else \
        np.all(np.isfinite(st.posture.positions[r]), axis=(1, 2))
    # This tick's pose was laid out by MotionPlayback with the old leg length.
    world = st.poses.root_position[r, :2] * old_leg
    placed = world.copy()
    for xy, heading in ((st.placement_xy, st.placement_heading),
                        (st.fade_placement_xy, st.fade_placement_heading)):
        unplaced = rotate_xy(world - xy[r], -heading[r]) / old_leg
        moved = rotate_xy(unplaced * new_leg, heading[r]) + xy[r]
        if xy is st.placement_xy:
            placed = np.where(played[:, None], world, moved)
        xy[r] += np.where(played[:, None], world - moved, 0.0)
    root = st.poses.root_position
    root[r, :2] = placed / new_leg
    st.lengths[r] = lengths[changed]
    st.segment_mass_kg[r], st.segment_com_fraction[r] = masses[changed], fractions[changed]
    st.locked[r] = False
