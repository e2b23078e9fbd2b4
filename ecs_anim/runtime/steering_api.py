"""The steering calls of :class:`~ecs_anim.runtime.simulation.Simulation` (docs/steering.md).

Between ticks, from a game loop or a scenario: give a character a locomotion set, a heading and
speed, a goal or a path. They only write the character's row of the store; the tick steers every
steered character at once (:func:`ecs_anim.runtime.steering.steer`, inside MotionPlayback).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

import numpy as np

from ecs_anim.core.checks import real_array, real_number
from ecs_anim.core.errors import EcsAnimError, UsageError, quoted
from ecs_anim.runtime.playback_queue import start_clips
from ecs_anim.runtime.steering import (
    GAITS,
    IDLE,
    STEER_HEADING,
    STEER_PATH,
    WALK,
    GaitTable,
    motion_root_xy,
)
from ecs_anim.runtime.store import MAX_WAYPOINTS

if TYPE_CHECKING:
    from ecs_anim.motion.sampling import ClipBank
    from ecs_anim.runtime.simulation import Simulation

#: Waypoints and speeds beyond this are refused (metres, m/s).
MAX_COORDINATE_M = 1e5
MAX_SPEED_M_S = 20.0


class SteeringCalls:
    """Mixed into :class:`~ecs_anim.runtime.simulation.Simulation`: the steering API."""

    _gaits: tuple[ClipBank, GaitTable] | None = None
    #: Entities that do not avoid the others (:meth:`set_avoidance`); replaced, not mutated.
    _not_avoiding: frozenset[int] = frozenset()

    def gait_table(self) -> GaitTable:
        """Each loaded clip's travel direction, own speed and foot phases (made once)."""
        bank = cast("Simulation", self).bank
        if self._gaits is None or self._gaits[0] is not bank:
            self._gaits = bank, GaitTable.from_bank(bank)
        return self._gaits[1]

    def set_locomotion(self, entity: int, walk: str, idle: str | None = None,
                       run: str | None = None) -> None:
        """Give a character a locomotion set: the clip played follows the speed steering asks
        for (``idle`` below the walk's slowest, ``run`` above its fastest). The character
        cross-fades to its idle clip now (its walk if it has none) unless it plays one of them.
        Clips are names of loaded motions; ``walk`` and ``run`` must travel."""
        sim = cast("Simulation", self)
        row = sim.row(entity)
        names = {"idle": idle, "walk": walk, "run": run}
        for gait, name in names.items():
            if not (isinstance(name, str) or (name is None and gait != "walk")):
                raise UsageError(f"locomotion {gait}: expected the name of a loaded motion, got "
                                 f"{type(name).__name__} {quoted(repr(name))}")
        clips = np.full(3, -1, np.int64)
        gaits = self.gait_table()
        for k, gait in enumerate(GAITS):
            name = names[gait]
            if name is None:
                continue
            try:
                clips[k] = sim.bank.index(name)
            except KeyError as exc:
                raise EcsAnimError(f"locomotion {gait}: {exc.args[0]}") from None
            if gait != "idle" and not gaits.speed_legs_s[clips[k]] > 1e-3:
                raise EcsAnimError(f"locomotion {gait}: motion {quoted(name)} does not travel "
                                   "(its root comes back to where it started)")
        st = sim.store
        st.gait_clip[row] = clips
        playing = np.flatnonzero(clips == st.clip[row])
        if playing.size:
            st.gait[row] = playing[0]
            st.loop[row] = True
            return
        first = IDLE if clips[IDLE] >= 0 else WALK
        rows = np.array([row])
        start_clips(st, sim.bank, rows, clips[[first]], np.zeros(1),
                    np.full(1, sim.steering_settings.gait_fade_s), np.ones(1, bool))
        st.gait[row] = first
        st.speed[row] = 1.0

    def _steered_row(self, entity: int, speed_m_s: float | None) -> int:
        """The character's row, made ready for steering (its clip its walk if it has no
        locomotion set); ``speed_m_s`` checked."""
        sim = cast("Simulation", self)
        row = sim.row(entity)
        if speed_m_s is not None:
            speed_m_s = real_number(speed_m_s, "speed_m_s")
        if speed_m_s is not None and not (np.isfinite(speed_m_s)
                                          and 0.0 <= speed_m_s <= MAX_SPEED_M_S):
            raise EcsAnimError(f"speed_m_s must be within 0-{MAX_SPEED_M_S:g} m/s, got {speed_m_s}")
        st = sim.store
        if st.gait_clip[row, WALK] < 0:
            clip = int(st.clip[row])
            if not self.gait_table().speed_legs_s[clip] > 1e-3:
                raise EcsAnimError(f"character {sim.names()[row]!r}: its motion "
                                   f"{quoted(sim.bank.names[clip])} does not travel; give it a "
                                   "locomotion set with a walk (set_locomotion)")
            st.gait_clip[row] = (-1, clip, -1)
            st.gait[row] = WALK
            st.loop[row] = True
        st.steer_speed_m_s[row] = np.nan if speed_m_s is None else speed_m_s
        return row

    def steer(self, entity: int, heading_rad: float | None = None,
              speed_m_s: float | None = None) -> None:
        """Steer a character by heading and speed from now on (call it every tick or once):
        it turns towards ``heading_rad`` (anticlockwise from +x; ``None``: the way it goes now)
        as fast as its steps allow and goes at ``speed_m_s`` (``None``: its walk's own speed;
        0 stops it on its idle motion). Cancels a path it was following."""
        sim = cast("Simulation", self)
        if heading_rad is not None and not np.isfinite(real_number(heading_rad, "heading_rad")):
            raise EcsAnimError(f"heading_rad must be finite, got {heading_rad}")
        row = self._steered_row(entity, speed_m_s)
        st = sim.store
        if heading_rad is None:
            heading_rad = float(st.placement_heading[row]
                                + self.gait_table().travel_rad[st.clip[row]])
        st.steer_heading_rad[row] = float(heading_rad)
        st.steer_mode[row] = STEER_HEADING

    def follow_path(self, entity: int, path_in_world: Sequence[Sequence[float]] | np.ndarray,
                    speed_m_s: float | None = None) -> None:
        """Walk a character along the waypoints ``path_in_world`` (k, 2) or (k, 3) (x, y
        metres; a z is ignored: the ground carries the feet), in order, from where it is, then
        stop on its idle motion at the last one. ``speed_m_s`` as for :meth:`steer`."""
        sim = cast("Simulation", self)
        if isinstance(path_in_world, (list, tuple)) and len(path_in_world) == 0:
            path_in_world = np.zeros((0, 2))
        try:
            points = real_array(path_in_world, (None, None), "path")
        except UsageError:
            raise UsageError("path: expected a list of [x, y] points, metres") from None
        if points.shape[1] not in (2, 3):
            raise EcsAnimError(f"path: expected a list of [x, y] points, got shape {points.shape}")
        if not 1 <= points.shape[0] <= MAX_WAYPOINTS - 1:
            raise EcsAnimError(f"path: expected 1 to {MAX_WAYPOINTS - 1} waypoints, got "
                               f"{points.shape[0]}")
        if not np.all(np.isfinite(points) & (np.abs(points) <= MAX_COORDINATE_M)):
            raise EcsAnimError(f"path: waypoints must be finite and within {MAX_COORDINATE_M:g} m")
        row = self._steered_row(entity, speed_m_s)
        st = sim.store
        rows = np.array([row])
        st.path_xy[row] = 0.0
        st.path_xy[row, 0] = motion_root_xy(sim.bank, st, rows)[0]
        st.path_xy[row, 1:points.shape[0] + 1] = points[:, :2]
        st.path_len[row] = points.shape[0] + 1
        steps = np.linalg.norm(np.diff(st.path_xy[row, :points.shape[0] + 1], axis=0), axis=1)
        st.path_cum_m[row] = 0.0
        st.path_cum_m[row, 1:points.shape[0] + 1] = np.cumsum(steps)
        st.path_cum_m[row, points.shape[0] + 1:] = st.path_cum_m[row, points.shape[0]]
        st.path_progress_m[row] = 0.0
        st.steer_mode[row] = STEER_PATH
        sim.reactions.path_given(entity)

    def walk_to(self, entity: int, goal_in_world: Sequence[float],
                speed_m_s: float | None = None) -> None:
        """Walk a character to ``goal_in_world`` (x, y[, z]) metres and stop there on its idle
        motion: :meth:`follow_path` with one waypoint (a goal behind it is turned to on the
        spot first)."""
        goal = real_array(goal_in_world, (None,), "walk_to: goal_in_world")
        self.follow_path(entity, goal[None], speed_m_s)

    def set_avoidance(self, entity: int, on: bool) -> None:
        """Whether a steered character avoids the other steered characters (local avoidance,
        ORCA: docs/steering.md; on by default, for every character, while
        ``steering_settings.avoidance`` is True). A character switched off keeps to its path or
        heading and speed, and the others avoid it in full."""
        sim = cast("Simulation", self)
        sim.row(entity)
        if not isinstance(on, (bool, np.bool_)):
            raise UsageError(f"set_avoidance: on: expected true or false, got "
                             f"{type(on).__name__} {quoted(repr(on))}")
        self._not_avoiding = (self._not_avoiding - {entity}) if on else (
            self._not_avoiding | {entity})

    def avoids(self, entity: int) -> bool:
        """Whether a character avoids the others when steered (:meth:`set_avoidance`)."""
        sim = cast("Simulation", self)
        sim.row(entity)
        return sim.steering_settings.avoidance and entity not in self._not_avoiding

    def not_avoiding(self) -> np.ndarray:
        """(k,) int64: the entities switched off by :meth:`set_avoidance`, sorted."""
        return np.array(sorted(self._not_avoiding), np.int64)

    def arrived(self, entity: int) -> bool:
        """Whether a character given a path or goal has reached its end (or was never given
        one). The tick it reaches it has an ``arrived`` event (docs/events.md)."""
        sim = cast("Simulation", self)
        return bool(sim.store.steer_mode[sim.row(entity)] != STEER_PATH)
