"""A simulation: one named esper world, a fixed time step, the schedule, the character store.

Nothing is global: each :class:`Simulation` makes its own esper world (a unique name) and
switches to it only for the duration of its own calls, so two simulations in one process, or
two tests, never see each other's entities.
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import esper
import numpy as np
from numpy.typing import NDArray

from .components import (
    Body,
    CharacterRow,
    MotionPlayer,
    Name,
    NormalizedPose,
    Placement,
    Posture,
    QueuedClip,
)
from .components import GroundQuery
from .errors import EcsAnimError
from .ground import Ground, Plane
from .morphology import Morphology, leg_length
from .motion import NormalizedMotion
from .playback import ClipBank, _wrap
from .store import CharacterStore
from .system_base import System

_counter = itertools.count()


class Simulation:
    """Characters playing normalized motions on a ground, stepped at a fixed rate.

    Parameters
    ----------
    motions : name -> motion, the clips characters may play.
    ground : the ground (default: the plane z = 0).
    fps : simulation ticks per second.
    window : also schedule Render (a viewer sets ``renderer``).
    vertebrae : if > 0, PostureConvert also resamples each spine into this many vertebra joints
        (``store.vertebrae``, (n, vertebrae, 3)) for output skeletons with more spine joints.
    """

    def __init__(self, motions: dict[str, NormalizedMotion], ground: Ground | None = None,
                 fps: float = 30.0, window: bool = False, vertebrae: int = 0):
        from .systems import HEADLESS, SCHEDULE

        if not motions:
            raise EcsAnimError("a simulation needs at least one motion")
        if not (np.isfinite(fps) and fps > 0):
            raise EcsAnimError(f"fps must be a positive number, got {fps}")
        self.world = f"ecs_anim-{next(_counter)}-{id(self):x}"
        if vertebrae < 0:
            raise EcsAnimError(f"vertebrae must be >= 0, got {vertebrae}")
        self.vertebrae = int(vertebrae)
        self.dt = 1.0 / fps
        self.fps = fps
        self.tick = 0
        self.bank = ClipBank.from_motions(motions)
        self.ground: Ground = ground or Plane()
        self.store = CharacterStore()
        self.renderer: object | None = None
        self.messages: list[str] = []
        schedule = SCHEDULE if window else HEADLESS
        self.systems: list[System] = []
        with self._active():
            esper.create_entity(GroundQuery(self.ground))
            for order, cls in enumerate(schedule):
                system = cls(self)
                # esper runs higher priorities first: derive them from the declared order.
                esper.add_processor(system, priority=len(schedule) - order)
                self.systems.append(system)

    @property
    def time_s(self) -> float:
        return self.tick * self.dt

    @contextmanager
    def _active(self) -> Iterator[None]:
        previous = esper.current_world
        esper.switch_world(self.world)
        try:
            yield
        finally:
            esper.switch_world(previous)

    def close(self) -> None:
        """Delete this simulation's esper world."""
        if self.world in esper.list_worlds():
            if esper.current_world == self.world:
                esper.switch_world("default")
            esper.delete_world(self.world)

    # --- characters -------------------------------------------------------------------------

    def spawn(self, name: str, body: Morphology, player: MotionPlayer,
              placement: Placement = Placement(), team: str = "") -> int:
        """Add a character; returns its entity. Validates at the boundary (not in the tick)."""
        clip = self.bank.index(player.clip)
        for q in player.queue:
            self.bank.index(q.clip)
        if not all(np.isfinite(v) for v in (*placement.position_m, placement.heading_rad,
                                             player.speed, player.start_s)):
            raise EcsAnimError(f"character {name!r}: placement, speed and start must be finite")
        with self._active():
            entity = esper.create_entity()
            row = self.store.add_row(
                entity=entity, lengths=body.lengths, clip=clip, clip_time_s=player.start_s,
                speed=player.speed, loop=player.loop, placement_xy=placement.position_m,
                placement_heading=placement.heading_rad, queue=list(player.queue),
                queue_len=len(player.queue),
                next_fade_s=player.queue[0].crossfade_s if player.queue else 0.0,
                ground_ref=float(self.ground.height(np.array(placement.position_m, float))),
            )
            for component in (Name(name, team), Body(body), player, placement, CharacterRow(row),
                              NormalizedPose(row), Posture(row)):
                esper.add_component(entity, component)
        return entity

    def row(self, entity: int) -> int:
        with self._active():
            return esper.component_for_entity(entity, CharacterRow).row

    def set_body(self, entity: int, body: Morphology) -> None:
        """Replace a character's morphology while it plays (paper §6)."""
        with self._active():
            esper.add_component(entity, Body(body))
            self.store.lengths[esper.component_for_entity(entity, CharacterRow).row] = body.lengths

    def names(self) -> list[str]:
        with self._active():
            by_row = {r.row: n.name for _, (r, n) in esper.get_components(CharacterRow, Name)}
        return [by_row[i] for i in range(self.store.n)]

    def leg_length(self) -> NDArray[np.float64]:
        """(n,) each character's leg length (mean thigh + shank), metres."""
        return leg_length(self.store.lengths)

    def start_next_clip(self, row: int) -> None:
        """Begin the next queued clip of one character, crossfading from the current one and
        continuing its root path (called by MotionPlayback when a clip is about to end)."""
        st, bank = self.store, self.bank
        queued: QueuedClip = st.queue[row].pop(0)  # type: ignore[assignment]
        new_clip = bank.index(queued.clip)
        # Where the old clip has the root now, in the world, and where the new one starts.
        from .playback import sample

        idx = np.array([row])
        old = sample(bank, st.clip[idx], st.clip_time_s[idx], st.loop[idx])
        new = sample(bank, np.array([new_clip]), np.zeros(1), np.array([queued.loop]))
        leg = self.leg_length()[row]
        heading = st.placement_heading[row]
        c, s = np.cos(heading), np.sin(heading)
        old_xy = np.array([[c, -s], [s, c]]) @ (old.root_position[0, :2] * leg) + st.placement_xy[row]
        new_heading = _wrap(old.root_heading[0] + heading - new.root_heading[0])
        c, s = np.cos(new_heading), np.sin(new_heading)
        st.fade_placement_xy[row] = st.placement_xy[row]
        st.fade_placement_heading[row] = st.placement_heading[row]
        st.placement_heading[row] = new_heading
        st.placement_xy[row] = old_xy - np.array([[c, -s], [s, c]]) @ (new.root_position[0, :2] * leg)
        st.fade_clip[row], st.fade_time_s[row], st.fade_loop[row] = st.clip[row], st.clip_time_s[row], st.loop[row]
        st.fade_s[row], st.fade_elapsed_s[row] = max(queued.crossfade_s, 0.0), 0.0
        st.clip[row], st.clip_time_s[row], st.loop[row] = new_clip, 0.0, queued.loop
        st.queue_len[row] = len(st.queue[row])
        st.next_fade_s[row] = st.queue[row][0].crossfade_s if st.queue[row] else 0.0  # type: ignore[attr-defined]
        with self._active():
            entity = int(st.entity[row])
            player = esper.component_for_entity(entity, MotionPlayer)
            esper.add_component(entity, replace(player, clip=queued.clip, loop=queued.loop,
                                                queue=tuple(st.queue[row])))  # type: ignore[arg-type]
            esper.add_component(entity, Placement(tuple(st.placement_xy[row]), float(new_heading)))  # type: ignore[arg-type]

    def report_frozen(self, rows: NDArray[np.int64]) -> None:
        """A character's pose went non-finite: it keeps its last good posture; say so once."""
        names = self.names()
        for r in rows:
            message = (f"warning: t={self.time_s:.3f} s: character {names[int(r)]!r} got a "
                       "non-finite pose and holds its last good posture; the others go on")
            self.messages.append(message)
            print(message, file=sys.stderr)

    # --- running ----------------------------------------------------------------------------

    def step(self) -> None:
        """Advance one fixed tick through the schedule."""
        with self._active():
            esper.process(self.dt)
        self.tick += 1

    def system_seconds(self) -> dict[str, float]:
        """Wall seconds spent in each system so far."""
        return {type(s).__name__: s.seconds for s in self.systems}
