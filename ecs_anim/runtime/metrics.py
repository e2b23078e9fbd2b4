"""Per-character quality figures of a run, recorded after every tick (all characters at once).

* foot sliding: how far a fully planted ankle moves from one tick to the next (mm per frame),
  and each slide beyond :data:`SLIDE_EVENT_MM` as an event naming the character, foot and tick;
* ground penetration: how far the heel (the sole under the ankle) or the sole under the ball of
  the foot goes below the ground (mm); floating: how far a fully planted foot's lower of the two
  stays above it (mm);
* bone-length error: the largest difference between a bone and the morphology (m);
* stride: distance between successive footprints of the same foot, also per leg length;
* time per system per tick.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.ground_adapt import BALL_HEIGHT_PER_LEG, heel_depth
from ecs_anim.core.morphology import bone_lengths_of
from ecs_anim.core.normalized import SIDE_JOINTS, SIDE_LENGTHS
from ecs_anim.core.skeleton import BONE_JOINTS
from ecs_anim.motion.constraint_table import KIND_NAMES, KIND_ORIENTATION
from ecs_anim.runtime.simulation import Simulation

ANKLES, TOES = list(SIDE_JOINTS["ankle"]), list(SIDE_JOINTS["toe"])
IS_BONE = np.array([a >= 0 for a, _ in BONE_JOINTS])


KIND_BY_NUMBER = {number: name for name, number in KIND_NAMES.items()}
#: A planted foot moving more than this in one tick (mm) is recorded as a slide event.
SLIDE_EVENT_MM = 1.0
#: Slide events kept (the first ones; the count goes on).
MAX_SLIDE_EVENTS = 100


class MetricsRecorder:
    """Call :meth:`record` after each :meth:`Simulation.step`; :meth:`report` at the end."""

    def __init__(self, sim: Simulation):

        self.sim = sim
        n = sim.store.n
        self.prev_ankles: np.ndarray | None = None
        self.prev_planted = np.zeros((n, 2), bool)
        self.slide_max = np.zeros(n)
        self.slide_sum = np.zeros(n)
        self.slide_count = np.zeros(n)
        self.slides: list[dict[str, Any]] = []
        self.slide_events = 0
        self.penetration_max = np.zeros(n)
        self.floating_max = np.zeros(n)
        self.bone_error_max = np.zeros(n)
        self.prev_locked = np.zeros((n, 2), bool)
        self.strides: list[list[float]] = [[] for _ in range(n)]
        self.last_print: list[list[np.ndarray | None]] = [[None, None] for _ in range(n)]
        m = sim.constraints.m
        self.constraint_error_full = np.full(m, np.nan)  # max while fully active (weight 1)
        self.constraint_error_any = np.full(m, np.nan)  # max while active at all
        self.com_error_max = np.full(n, np.nan)
        self.ticks = 0

    def record(self) -> None:
        """Take this tick's figures from the store (all characters at once); call it after each
        :meth:`Simulation.step`."""
        sim, st = self.sim, self.sim.store
        if st.n != self.slide_max.shape[0]:
            raise EcsAnimError("MetricsRecorder: characters were added or removed after it was "
                               "made; make a new recorder after changing who is simulated")
        p = st.positions
        ankles, toes = p[:, ANKLES], p[:, TOES]
        planted = st.contact_weight >= 1.0
        if self.prev_ankles is not None:
            both = planted & self.prev_planted
            move_mm = np.linalg.norm(ankles - self.prev_ankles, axis=-1) * 1e3
            move_mm = np.where(both, move_mm, 0.0)
            self.slide_max = np.maximum(self.slide_max, move_mm.max(axis=1))
            self.slide_sum += move_mm.sum(axis=1)
            self.slide_count += both.sum(axis=1)
            if np.any(move_mm > SLIDE_EVENT_MM):  # rare: only then are the rows visited
                self._record_slides(move_mm)
        self.prev_ankles, self.prev_planted = ankles.copy(), planted
        ankle_height = st.lengths[:, SIDE_LENGTHS["ankle_height"]]
        ball = BALL_HEIGHT_PER_LEG * sim.leg_length()[:, None]
        toe_depth = sim.ground.height(toes[..., :2]) - (toes[..., 2] - ball)
        heel = heel_depth(sim.ground, ankles, ankle_height)
        depth_mm = np.maximum(heel, toe_depth).max(axis=1) * 1e3
        self.penetration_max = np.maximum(self.penetration_max, depth_mm)
        # A fully planted foot floats by how far the lower of its heel and ball is above ground.
        float_mm = np.where(planted, -np.maximum(heel, toe_depth), 0.0).max(axis=1) * 1e3
        self.floating_max = np.maximum(self.floating_max, float_mm)
        error = np.abs(bone_lengths_of(p)[:, IS_BONE] - st.lengths[:, IS_BONE]).max(axis=1)
        self.bone_error_max = np.maximum(self.bone_error_max, error)
        # Strides: a new footprint is laid (an event; only those feet are visited).
        new = st.locked & ~self.prev_locked
        for row, side in zip(*np.nonzero(new), strict=False):
            here = st.footprint[row, side, :2].copy()
            last = self.last_print[row][side]
            if last is not None:
                self.strides[row].append(float(np.linalg.norm(here - last)))
            self.last_print[row][side] = here
        self.prev_locked = st.locked.copy()
        table = sim.constraints
        if table.m:
            err = table.error
            full = (table.weight >= 1.0) & np.isfinite(err)
            self.constraint_error_full = np.where(full, np.fmax(self.constraint_error_full, err),
                                                  self.constraint_error_full)
            self.constraint_error_any = np.fmax(self.constraint_error_any, err)
            self.com_error_max = np.fmax(self.com_error_max, st.com_error_m)
        self.ticks += 1

    def _record_slides(self, move_mm: np.ndarray) -> None:
        rows, sides = np.nonzero(move_mm > SLIDE_EVENT_MM)
        self.slide_events += rows.size
        room = MAX_SLIDE_EVENTS - len(self.slides)
        if room <= 0:
            return
        names = self.sim.names()
        tick = self.sim.tick - 1  # the posture recorded is the last tick stepped
        for row, side in zip(rows[:room], sides[:room], strict=False):
            self.slides.append({"tick": tick, "time_s": round(self.sim.posture_time_s, 4),
                                "character": names[row], "foot": "left" if side == 0 else "right",
                                "mm": round(float(move_mm[row, side]), 3)})

    def report(self) -> dict[str, Any]:
        """The figures so far, as ``ecs-anim run --report`` writes them: ``characters`` (per
        character: foot sliding mm per frame max/mean, penetration and floating mm, bone-length
        error m, stride m and per leg length, COM error mm), ``constraints`` (per constraint: its
        largest error while fully active and while active, mm, or mrad for an orientation),
        ``ms_per_tick`` per system, ``slide_events``, ``messages``."""
        sim = self.sim
        names = sim.names()
        legs = sim.leg_length()
        characters = []
        for i, name in enumerate(names):
            strides = np.array(self.strides[i])
            characters.append({
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
                "frozen": bool(sim.store.frozen[i]),
                "com_error_mm_max": None if np.isnan(self.com_error_max[i])
                else round(float(self.com_error_max[i]) * 1e3, 3),
            })
        table = sim.constraints
        constraints = [{
            "name": table.names[k], "character": names[int(table.owner[k])],
            "kind": KIND_BY_NUMBER[int(table.kind[k])],
            # an orientation's error is an angle: these figures are then milliradians
            "unit": "mrad" if int(table.kind[k]) == KIND_ORIENTATION else "mm",
            "error_mm_max_fully_active": None if np.isnan(self.constraint_error_full[k])
            else round(float(self.constraint_error_full[k]) * 1e3, 3),
            "error_mm_max_active": None if np.isnan(self.constraint_error_any[k])
            else round(float(self.constraint_error_any[k]) * 1e3, 3),
            "enabled": bool(table.enabled[k]),
        } for k in range(table.m)]
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
