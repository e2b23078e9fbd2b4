"""A body replaced while the character plays (paper §6): MorphologyAdapt takes it in.

``Simulation.set_body`` replaces the character's Morphology component (a structural change).
At once (``blend_s`` 0): on the next tick, before decoding, MorphologyAdapt runs
:func:`adopt_bodies`: the rows whose component differs from the store get the new segment
lengths and masses, and because the root path is stored in leg lengths (a new leg length would
move the character along its path), their placement is shifted so the character stays where it
is (:func:`keep_in_place`); its feet re-plant. Blended (``blend_s`` > 0, a :class:`BodyBlend`
component): every tick :func:`blend_bodies` moves the store's lengths and masses a step from
the old body toward the new one (a smoothstep over ``blend_s``), shifting the placement the same
way so the root's path stays continuous, and keeps planted feet on their footprints (they
are not released; a foot's ankle height changes while it is off the ground).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ecs_anim.components import BodyBlend
from ecs_anim.core.morphology import DE_LEVA_1996, MASS_SEGMENTS, Morphology, leg_length
from ecs_anim.core.skeleton import LENGTH_INDEX
from ecs_anim.motion.constraints import ramp_weight
from ecs_anim.motion.sampling import rotate_xy

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation


def mass_tables(bodies: list[Morphology]) -> tuple[np.ndarray, np.ndarray]:
    """Each body's de Leva segment masses (kg) and centre-of-mass fractions, (k, segments)
    each: :func:`ecs_anim.core.morphology.segment_mass_table` for many bodies at once."""
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
    blending, _ = sim.rows_and_components(BodyBlend)
    if blending.size:  # blended by blend_bodies, tick by tick
        keep = ~np.isin(rows, blending)
        rows, bodies = rows[keep], [b for b, k in zip(bodies, keep, strict=True) if k]
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
    # Only a character that has played keeps its place; one replaced before its first tick
    # starts from its placement on the new body.
    played = np.zeros(r.shape, bool) if st.posture is None else \
        np.all(np.isfinite(st.posture.positions[r]), axis=(1, 2))
    keep_in_place(sim, r, lengths[changed], played)
    st.lengths[r] = lengths[changed]
    st.segment_mass_kg[r], st.segment_com_fraction[r] = masses[changed], fractions[changed]
    st.locked[r] = False


def keep_in_place(sim: Simulation, r: np.ndarray, new_lengths: np.ndarray,
                  played: np.ndarray) -> None:
    """Before rows ``r`` (k,) take ``new_lengths`` (k, N_LENGTHS): shift their placements (and
    those of a clip fading out) so that the root stays where this tick's pose, laid out with the
    old leg length, put it (``played`` (k,) True), or so that a character that has not played
    yet starts from its placement on the new body (False). Writes placement_xy,
    fade_placement_xy and the root of this tick's poses."""
    st = sim.store
    old_leg = leg_length(st.lengths[r])[:, None]
    new_leg = leg_length(new_lengths)[:, None]
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
    st.poses.root_position[r, :2] = placed / new_leg


def start_blend(sim: Simulation, row: int, start_s: float, blend_s: float) -> BodyBlend:
    """The BodyBlend component of a body change of the character in store ``row`` beginning at
    ``start_s`` and lasting ``blend_s`` seconds, from the body it has in the store now."""
    st = sim.store
    return BodyBlend(tuple(st.lengths[row]), tuple(st.segment_mass_kg[row]),
                     tuple(st.segment_com_fraction[row]), float(start_s), float(blend_s))


ANKLE_HEIGHTS = [LENGTH_INDEX["ankle_height_l"], LENGTH_INDEX["ankle_height_r"]]


#: How long after a blend's time a planted foot's ankle height still waits for the foot to
#: swing (s): longer than a walk's stance.
SWING_WAIT_S = 1.0


def blend_bodies(sim: Simulation) -> None:
    """One tick of every body change in progress (between MotionPlayback and the decode of
    MorphologyAdapt): lengths and masses at the smoothstep of the elapsed fraction between the
    BodyBlend's old body and the Morphology component's new one, all blending rows at once.

    A foot's ankle height (its sole under the ankle) changes only while that foot is off the
    ground, at most three times the blend's mean rate a tick, so a planted ankle does not move at all
    (its footprint holds); what is left :data:`SWING_WAIT_S` after the blend time follows then,
    planted or not (a character standing through the whole blend: its ankles rise as slowly). Writes
    store.lengths, segment_mass_kg, segment_com_fraction, placement_xy, fade_placement_xy and the
    root of this tick's poses (footprints lie on the ground whatever the body: they stay)."""
    st = sim.store
    rows, blends = sim.rows_and_components(BodyBlend)
    if rows.size == 0:
        return
    now = sim.time_s
    body_of = dict(zip(*sim.rows_and_components(Morphology), strict=True))
    to_lengths = np.array([body_of[int(r)].lengths for r in rows])
    going = np.array([now <= b.start_s + b.blend_s + sim.dt for b in blends]) | \
        np.any(st.lengths[rows] != to_lengths, axis=1)
    if not going.any():
        return
    rows, blends, to_lengths = rows[going], [b for b, g in zip(blends, going, strict=True) if g], \
        to_lengths[going]
    start = np.array([b.start_s for b in blends])
    length = np.array([b.blend_s for b in blends])
    from_lengths = np.array([b.from_lengths for b in blends])
    to_masses, to_fractions = mass_tables([body_of[int(r)] for r in rows])
    # Smooth in and out (ramp_weight's quintic): no joint set moving by the change at once.
    s = ramp_weight(np.full(rows.size, now), start, np.inf, length, 0.0)[:, None]
    lengths = from_lengths * (1 - s) + to_lengths * s
    masses = np.array([b.from_mass_kg for b in blends]) * (1 - s) + to_masses * s
    fractions = np.array([b.from_com_fraction for b in blends]) * (1 - s) + to_fractions * s
    ankle_now = st.lengths[rows][:, ANKLE_HEIGHTS]
    limit = 3.0 * np.abs(to_lengths - from_lengths)[:, ANKLE_HEIGHTS] * sim.dt / length[:, None]
    waiting = now < start + length + SWING_WAIT_S  # for a swing to change its ankle height in
    held = (st.locked[rows] | (st.contact_weight[rows] > 0.0)) & waiting[:, None]
    ankle = np.where(held, ankle_now,
                     ankle_now + np.clip(lengths[:, ANKLE_HEIGHTS] - ankle_now, -limit, limit))
    lengths[:, ANKLE_HEIGHTS] = ankle
    keep_in_place(sim, rows, lengths, np.ones(rows.size, bool))
    st.lengths[rows] = lengths
    st.segment_mass_kg[rows], st.segment_com_fraction[rows] = masses, fractions
