"""DetectEvents: the tick is over: advance the clock, then find its events and fire the triggers.

Runs after PostureConvert (and with no character too), so that every event is seen on the
posture this tick made: clips started and ended, foot contacts begun, paths' ends reached
(arrived), points come near each other, constraints reached (:meth:`ecs_anim.runtime.events.Reactions.after_tick`). The clock
moves first (``sim.tick``), so an action fired here acts from the next tick on, as one made
between two ticks does.

Reads: store.clip, clip_time_s, contact_weight, steer_mode, path_xy, path_len, path_cum_m,
path_progress_m, positions, constraints.error; the reactions.
Writes: the clock (``sim.tick``), the events (``sim.events()``), and through the actions of the
triggers that fire (as ApplyReactions): constraints.target_world, constraints.activation,
constraints.enabled, queue_clip, queue_fade_s, queue_loop, queue_len, queue_head, clip,
clip_time_s, loop, fade_* (fade_clip, fade_time_s, fade_loop, fade_s, fade_elapsed_s,
fade_keeps_contacts, fade_speed, fade_placement_xy, fade_placement_heading), placement_xy,
placement_heading, locked; the Morphology component; characters removed.
"""

from __future__ import annotations

from typing import ClassVar

from ecs_anim.runtime.system_base import System
from ecs_anim.systems.apply_reactions import REACTION_WRITES


class DetectEvents(System):
    runs_without_characters: ClassVar[bool] = True
    reads = ("clip", "clip_time_s", "contact_weight", "steer_mode", "path_xy", "path_len",
             "path_cum_m", "path_progress_m", "positions", "constraints.error")
    writes = REACTION_WRITES

    def run(self, dt: float) -> None:
        self.sim.tick += 1
        self.sim.reactions.after_tick(self.sim)
