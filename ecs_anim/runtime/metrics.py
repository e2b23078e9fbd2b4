"""Per-character quality figures of a run, recorded after every tick (all characters at once).

* foot sliding: how far the sole point a fully planted foot stood on (its heel under the ankle,
  or its ball under the toe joint: ``store.pivot``) at one tick moves by the next (mm per frame;
  a foot rolling from heel to ball turns about the one point, then stands on the other), and each slide beyond :data:`SLIDE_EVENT_MM` as an event naming the character, foot
  and tick;
* ground penetration: how far the heel (the sole under the ankle) or the sole under the ball of
  the foot goes below the ground (mm); floating: how far a fully planted foot's lower of the two
  stays above it (mm);
* bone-length error: the largest difference between a bone and the morphology (m);
* overlap: the deepest overlap of a character's collision capsules with another character's
  after separation (mm; ``store.overlap_m``, CollisionSeparate), and the time it was deepest;
* joint speed: each character's fastest joint (m/s, between two ticks) and the fastest joint of
  its motion's own pose (before the solver: ``store.clip_positions``), and when: a joint much
  faster than the motion's own is a pop (``SolverSettings.max_joint_speed_m_s`` bounds them);
* stride: distance between successive footprints of the same foot, also per leg length (the
  median of the latest :data:`STRIDES_KEPT`);
* time per system per tick.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground_adapt import BALL_HEIGHT_PER_LEG, heel_depth
from ecs_anim.core.morphology import bone_lengths_of
from ecs_anim.core.normalized import SIDE_JOINTS, SIDE_LENGTHS
from ecs_anim.core.skeleton import BONE_JOINTS, N_JOINTS
from ecs_anim.motion.constraint_table import KIND_NAMES, KIND_ORIENTATION
from ecs_anim.runtime.simulation import Simulation

ANKLES, TOES = list(SIDE_JOINTS["ankle"]), list(SIDE_JOINTS["toe"])
IS_BONE = np.array([a >= 0 for a, _ in BONE_JOINTS])


KIND_BY_NUMBER = {number: name for name, number in KIND_NAMES.items()}
#: A planted foot moving more than this in one tick (mm) is recorded as a slide event.
SLIDE_EVENT_MM = 1.0
#: Slide events kept (the first ones; the count goes on).
MAX_SLIDE_EVENTS = 100
#: Strides kept per character for its median stride (the latest ones): the recorder's memory
#: stays flat however long the run (it grew with every footstep: 194 to 224 MB over 30 minutes).
STRIDES_KEPT = 256


#: The recorder's per-character arrays (one row per character it has seen) and the value a
#: character seen for the first time starts with.
CHARACTER_FIGURES = (("prev_soles", 0.0), ("prev_pivot", 0), ("prev_planted", False),
                     ("prev_locked", False), ("slide_max", 0.0), ("slide_sum", 0.0), ("slide_count", 0.0),
                     ("penetration_max", 0.0), ("floating_max", 0.0), ("bone_error_max", 0.0),
                     ("com_error_max", np.nan), ("overlap_max", 0.0), ("overlap_at_s", np.nan),
                     ("leg_length_m", 0.0), ("frozen", False),
                     ("removed_at_s", np.nan), ("prev_joints", np.nan), ("prev_clip_joints", np.nan),
                     ("joint_speed_max", 0.0), ("clip_joint_speed_max", 0.0),
                     ("joint_speed_at_s", np.nan))
#: The same for the per-constraint arrays.
CONSTRAINT_FIGURES = (("constraint_error_full", np.nan), ("constraint_error_any", np.nan),
                      ("constraint_enabled", False))


class MetricsRecorder:
    """Call :meth:`record` after each :meth:`Simulation.step`; :meth:`report` at the end.

    Figures are kept per character and per constraint, in the order they were first seen (the
    store's and the constraint table's at first), keyed by entity and by constraint id, never
    by row: a character removed mid-run keeps the figures it had until then (its row gone and
    the rows after it moved down), one spawned mid-run has its own from its first tick, and
    the report lists every character and constraint the run had."""

    def __init__(self, sim: Simulation):
        self.sim = sim
        # per character (k, ...): its entity and name, then :data:`CHARACTER_FIGURES`: the last
        # tick's sole points (k, 2, 2, 3: per foot its heel, its ball), the one each foot stood on
        # (k, 2) and planted and locked feet (k, 2), the figures, its last
        # recorded leg length (m) and frozen flag, and the time of the first recorded posture
        # it was missing from (NaN: still simulated)
        self.entities = np.zeros(0, np.int64)
        self.names: list[str] = []
        self.prev_soles = np.zeros((0, 2, 2, 3))
        self.prev_pivot = np.zeros((0, 2), np.int64)
        self.prev_planted = np.zeros((0, 2), bool)
        self.prev_locked = np.zeros((0, 2), bool)
        self.slide_max = np.zeros(0)
        self.slide_sum = np.zeros(0)
        self.slide_count = np.zeros(0)
        self.penetration_max = np.zeros(0)
        self.floating_max = np.zeros(0)
        self.bone_error_max = np.zeros(0)
        self.com_error_max = np.zeros(0)
        self.overlap_max = np.zeros(0)
        self.overlap_at_s = np.zeros(0)
        self.leg_length_m = np.zeros(0)
        self.frozen = np.zeros(0, bool)
        self.removed_at_s = np.zeros(0)
        # the last tick's joints of the posture and of the motion's own pose (k, N_JOINTS, 3;
        # NaN: none yet), the fastest joint of each (m/s) and when the posture's was fastest
        self.prev_joints = np.zeros((0, N_JOINTS, 3))
        self.prev_clip_joints = np.zeros((0, N_JOINTS, 3))
        self.joint_speed_max = np.zeros(0)
        self.clip_joint_speed_max = np.zeros(0)
        self.joint_speed_at_s = np.zeros(0)
        self.strides: list[deque[float]] = []
        self.last_print: list[list[np.ndarray | None]] = []
        self.slides: list[dict[str, Any]] = []
        self.slide_events = 0
        # per constraint (c,): its id, name, owner's name and kind, then
        # :data:`CONSTRAINT_FIGURES`: its largest error while fully active (weight 1) and while
        # active at all, whether it was switched on at its last recorded tick
        self.constraint_uids = np.zeros(0, np.int64)
        self.constraint_names: list[str] = []
        self.constraint_owners: list[str] = []
        self.constraint_kinds = np.zeros(0, np.int64)
        self.constraint_error_full = np.zeros(0)
        self.constraint_error_any = np.zeros(0)
        self.constraint_enabled = np.zeros(0, bool)
        self._character_of = np.zeros(0, np.int64)  # entity id -> its index here (-1: unseen)
        self._constraint_of = np.zeros(0, np.int64)  # constraint id -> its index here
        self.ticks = 0
        self._characters()
        self._constraints()

    def record(self) -> None:
        """Take this tick's figures from the store (all characters at once); call it after each
        :meth:`Simulation.step`."""
        sim, st = self.sim, self.sim.store
        at = self._characters()  # (n,) each store row's index in the per-character arrays
        gone = np.ones(self.entities.shape[0], bool)
        gone[at] = False
        self.removed_at_s[gone & np.isnan(self.removed_at_s)] = sim.posture_time_s
        p = st.positions
        ankles, toes = p[:, ANKLES], p[:, TOES]
        legs = sim.leg_length()
        ankle_height = st.lengths[:, SIDE_LENGTHS["ankle_height"]]
        ball = BALL_HEIGHT_PER_LEG * legs[:, None]
        soles = np.stack([ankles, toes], axis=2)  # (n, 2, 2, 3): per foot its heel, its ball
        soles[..., 2] -= np.stack([ankle_height, ball.repeat(2, axis=1)], axis=2)
        planted = st.contact_weight >= 1.0
        # (a character's first tick has nothing planted before: no slide)
        both = planted & self.prev_planted[at]
        pivot = self.prev_pivot[at][..., None, None]
        stands = np.take_along_axis(soles, pivot, axis=2)[:, :, 0]
        stood = np.take_along_axis(self.prev_soles[at], pivot, axis=2)[:, :, 0]
        move_mm = np.linalg.norm(stands - stood, axis=-1) * 1e3
        move_mm = np.where(both, move_mm, 0.0)
        self.slide_max[at] = np.maximum(self.slide_max[at], move_mm.max(axis=1))
        self.slide_sum[at] += move_mm.sum(axis=1)
        self.slide_count[at] += both.sum(axis=1)
        if np.any(move_mm > SLIDE_EVENT_MM):  # rare: only then are the rows visited
            self._record_slides(move_mm, at)
        self.prev_soles[at], self.prev_pivot[at], self.prev_planted[at] = soles, st.pivot, planted
        self.leg_length_m[at], self.frozen[at] = legs, st.frozen
        toe_depth = sim.ground.height(toes[..., :2]) - (toes[..., 2] - ball)
        heel = heel_depth(sim.ground, ankles, ankle_height)
        depth_mm = np.maximum(heel, toe_depth).max(axis=1) * 1e3
        self.penetration_max[at] = np.maximum(self.penetration_max[at], depth_mm)
        # A fully planted foot floats by how far the lower of its heel and ball is above ground.
        float_mm = np.where(planted, -np.maximum(heel, toe_depth), 0.0).max(axis=1) * 1e3
        self.floating_max[at] = np.maximum(self.floating_max[at], float_mm)
        self._record_speeds(at)
        error = np.abs(bone_lengths_of(p)[:, IS_BONE] - st.lengths[:, IS_BONE]).max(axis=1)
        self.bone_error_max[at] = np.maximum(self.bone_error_max[at], error)
        if st.overlap_m.shape[0] == st.n:
            deeper = st.overlap_m > self.overlap_max[at]
            self.overlap_max[at] = np.where(deeper, st.overlap_m, self.overlap_max[at])
            self.overlap_at_s[at[deeper]] = sim.posture_time_s
        # Strides: a new footprint is laid (an event; only those feet are visited).
        new = st.locked & ~self.prev_locked[at]
        for row, side in zip(*np.nonzero(new), strict=False):
            here = st.footprint[row, side, :2].copy()
            last = self.last_print[at[row]][side]
            if last is not None:
                self.strides[at[row]].append(float(np.linalg.norm(here - last)))
            self.last_print[at[row]][side] = here
        self.prev_locked[at] = st.locked
        table = sim.constraints
        which = self._constraints()  # (m,) each table row's index in the per-constraint arrays
        if table.m:
            err = table.error
            full = (table.weight >= 1.0) & np.isfinite(err)
            before = self.constraint_error_full[which]
            self.constraint_error_full[which] = np.where(full, np.fmax(before, err), before)
            self.constraint_error_any[which] = np.fmax(self.constraint_error_any[which], err)
            self.constraint_enabled[which] = table.enabled
            self.com_error_max[at] = np.fmax(self.com_error_max[at], st.com_error_m)
        self.ticks += 1

    def _record_speeds(self, at: NDArray[np.int64]) -> None:
        """The fastest joint of each character's posture and of its motion's own pose since the
        last tick (m/s; a character's first tick has none: NaN, ignored)."""
        st, dt = self.sim.store, self.sim.dt
        # (rows the frame budget did not solve are NaN there: their motion's pose is the posture's)
        clip = st.positions if st.clip_positions is None else \
            np.where(np.isnan(st.clip_positions), st.positions, st.clip_positions)
        speed = np.linalg.norm(st.positions - self.prev_joints[at], axis=-1).max(axis=1) / dt
        clip_speed = np.linalg.norm(clip - self.prev_clip_joints[at], axis=-1).max(axis=1) / dt
        faster = speed > self.joint_speed_max[at]  # (NaN: False)
        self.joint_speed_max[at[faster]] = speed[faster]
        self.joint_speed_at_s[at[faster]] = self.sim.posture_time_s
        self.clip_joint_speed_max[at] = np.fmax(self.clip_joint_speed_max[at], clip_speed)
        self.prev_joints[at], self.prev_clip_joints[at] = st.positions, clip

    def _characters(self) -> NDArray[np.int64]:
        """(n,) each store row's index in the per-character arrays; a character not seen before
        is added to them (its name read then: names are looked up only when someone is new)."""
        st = self.sim.store
        self._character_of = _id_table(self._character_of, st.entity)
        at = self._character_of[st.entity]
        new = np.flatnonzero(at < 0)
        if new.size:
            at[new] = self.entities.shape[0] + np.arange(new.size)
            self._character_of[st.entity[new]] = at[new]
            names = self.sim.names()
            self.entities = np.concatenate([self.entities, st.entity[new]])
            self.names += [names[r] for r in new.tolist()]
            for name, fill in CHARACTER_FIGURES:
                setattr(self, name, _grown(getattr(self, name), new.size, fill))
            self.leg_length_m[at[new]] = self.sim.leg_length()[new]
            self.frozen[at[new]] = st.frozen[new]
            self.strides += [deque(maxlen=STRIDES_KEPT) for _ in new]
            self.last_print += [[None, None] for _ in new]
        return at

    def _constraints(self) -> NDArray[np.int64]:
        """(m,) each constraint table row's index in the per-constraint arrays (a constraint not
        seen before added to them)."""
        table = self.sim.constraints
        self._constraint_of = _id_table(self._constraint_of, table.uid)
        which = self._constraint_of[table.uid]
        new = np.flatnonzero(which < 0)
        if new.size:
            which[new] = self.constraint_uids.shape[0] + np.arange(new.size)
            self._constraint_of[table.uid[new]] = which[new]
            owners = self._characters()[table.owner[new]]
            self.constraint_uids = np.concatenate([self.constraint_uids, table.uid[new]])
            self.constraint_names += [table.names[k] for k in new.tolist()]
            self.constraint_owners += [self.names[i] for i in owners.tolist()]
            self.constraint_kinds = np.concatenate([self.constraint_kinds, table.kind[new]])
            for name, fill in CONSTRAINT_FIGURES:
                setattr(self, name, _grown(getattr(self, name), new.size, fill))
            self.constraint_enabled[which[new]] = table.enabled[new]
        return which

    def _record_slides(self, move_mm: np.ndarray, at: NDArray[np.int64]) -> None:
        rows, sides = np.nonzero(move_mm > SLIDE_EVENT_MM)
        self.slide_events += rows.size
        room = MAX_SLIDE_EVENTS - len(self.slides)
        if room <= 0:
            return
        tick = self.sim.tick - 1  # the posture recorded is the last tick stepped
        for row, side in zip(rows[:room], sides[:room], strict=False):
            self.slides.append({"tick": tick, "time_s": round(self.sim.posture_time_s, 4),
                                "character": self.names[at[row]],
                                "foot": "left" if side == 0 else "right",
                                "mm": round(float(move_mm[row, side]), 3)})

    def report(self) -> dict[str, Any]:
        """The figures so far, as ``ecs-anim run --report`` writes them: ``characters`` (per
        character: foot sliding mm per frame max/mean, penetration and floating mm, bone-length
        error m, stride m and per leg length, COM error mm, deepest overlap with another character
        mm and when (s; None: none), fastest joint m/s and when, and the motion's own fastest
        joint m/s; ``removed_at_s``, only for one
        removed mid-run: the time of the first recorded posture without it, its figures ending
        there), ``constraints`` (per constraint, removed ones included: its largest error while
        fully active and while active, mm, or mrad for an orientation), ``ms_per_tick`` per
        system, ``slide_events``, ``messages``."""
        sim = self.sim
        at, which = self._characters(), self._constraints()
        legs, frozen = self.leg_length_m.copy(), self.frozen.copy()
        legs[at], frozen[at] = sim.leg_length(), sim.store.frozen  # as they are now
        enabled = self.constraint_enabled.copy()
        enabled[which] = sim.constraints.enabled
        characters = []
        for i, name in enumerate(self.names):
            strides = np.array(self.strides[i])
            figures = {
                "name": name,
                "leg_length_m": round(float(legs[i]), 4),
                "foot_sliding_mm_per_frame": {
                    "max": round(float(self.slide_max[i]), 4),
                    "mean": round(float(self.slide_sum[i] / max(self.slide_count[i], 1)), 4)},
                "ground_penetration_mm_max": round(float(max(self.penetration_max[i], 0.0)), 4),
                "floating_mm_max": round(float(self.floating_max[i]), 4),
                "bone_length_error_m_max": float(self.bone_error_max[i]),
                "stride_m_median": None if strides.size == 0 else round(float(np.median(strides)), 4),
                "stride_per_leg_length": None if strides.size == 0
                else round(float(np.median(strides) / legs[i]), 4),
                "frozen": bool(frozen[i]),
                "com_error_mm_max": None if np.isnan(self.com_error_max[i])
                else round(float(self.com_error_max[i]) * 1e3, 3),
                "overlap_mm_max": round(float(self.overlap_max[i]) * 1e3, 3),
                "overlap_at_s": None if np.isnan(self.overlap_at_s[i])
                else round(float(self.overlap_at_s[i]), 4),
                "joint_speed_m_s_max": round(float(self.joint_speed_max[i]), 3),
                "clip_joint_speed_m_s_max": round(float(self.clip_joint_speed_max[i]), 3),
                "joint_speed_at_s": None if np.isnan(self.joint_speed_at_s[i])
                else round(float(self.joint_speed_at_s[i]), 4),
            }
            if not np.isnan(self.removed_at_s[i]):
                figures["removed_at_s"] = round(float(self.removed_at_s[i]), 4)
            characters.append(figures)
        constraints = [{
            "name": self.constraint_names[k], "character": self.constraint_owners[k],
            "kind": KIND_BY_NUMBER[int(self.constraint_kinds[k])],
            # an orientation's error is an angle: these figures are then milliradians
            "unit": "mrad" if int(self.constraint_kinds[k]) == KIND_ORIENTATION else "mm",
            "error_mm_max_fully_active": None if np.isnan(self.constraint_error_full[k])
            else round(float(self.constraint_error_full[k]) * 1e3, 3),
            "error_mm_max_active": None if np.isnan(self.constraint_error_any[k])
            else round(float(self.constraint_error_any[k]) * 1e3, 3),
            "enabled": bool(enabled[k]),
        } for k in range(len(self.constraint_names))]
        ticks = max(self.ticks, 1)
        return {
            "seconds": round(sim.time_s, 4),
            "ticks": self.ticks,
            "fps": sim.fps,
            "characters": characters,
            "constraints": constraints,
            "ms_per_tick": {k: round(v / ticks * 1e3, 4) for k, v in sim.system_seconds().items()},
            "slide_events": {"count": self.slide_events, "threshold_mm": SLIDE_EVENT_MM,
                             "first": list(self.slides)},
            "messages": list(sim.messages),
        }


def _id_table(table: NDArray[np.int64], ids: NDArray[np.int64]) -> NDArray[np.int64]:
    """``table`` (id -> index, -1: none) long enough to look every one of ``ids`` up."""
    size = int(ids.max(initial=-1)) + 1
    if size <= table.shape[0]:
        return table
    return np.concatenate([table, np.full(size - table.shape[0], -1, np.int64)])


def _grown(values: NDArray[Any], k: int, fill: float | bool) -> NDArray[Any]:
    """``values`` with ``k`` more rows of ``fill`` (its dtype and trailing shape)."""
    return np.concatenate([values, np.full((k, *values.shape[1:]), fill, values.dtype)])
