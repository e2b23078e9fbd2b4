"""ApplyReactions: what is due before this tick's posture: moving targets, time triggers, delayed actions.

Runs first in the schedule (and with no character too: a time trigger still fires). The
reactions themselves (:class:`ecs_anim.runtime.events.Reactions`) are the simulation's
``sim.reactions``; this system applies, at the posture this tick makes (``sim.time_s``), the
target tracks (``Simulation.add_target_track``), the ``at_time`` triggers and the actions of
triggers whose delay has run out (play a clip, switch a constraint on or off, move its target,
change a body, remove a character, arm a trigger).

Reads: the reactions (tracks, triggers, pending actions), store.clip, clip_time_s.
Writes: constraints.target_world (tracks, move_target), constraints.activation and
constraints.enabled (switch_on, switch_off), queue_clip, queue_fade_s, queue_loop, queue_len,
queue_head and starting the clip (play): clip, clip_time_s, loop, fade_* (fade_clip,
fade_time_s, fade_loop, fade_s, fade_elapsed_s, fade_keeps_contacts, fade_speed,
fade_placement_xy, fade_placement_heading), placement_xy, placement_heading, locked; the
Morphology component (set_body); characters removed (remove).
"""

from __future__ import annotations

from typing import ClassVar

from ecs_anim.runtime.system_base import System
from ecs_anim.systems.queued_clips import CLIP_START_WRITES

#: What the actions of triggers write (play: the queue, then the clip starts; switch_on,
#: switch_off, move_target: the constraint's row of the table).
REACTION_WRITES = ("constraints.target_world", "constraints.activation", "constraints.enabled",
                   "queue_clip", "queue_fade_s", "queue_loop", "queue_len", "queue_head",
                   *CLIP_START_WRITES)


class ApplyReactions(System):
    runs_without_characters: ClassVar[bool] = True
    reads = ("clip", "clip_time_s")
    writes = REACTION_WRITES

    def run(self, dt: float) -> None:
        self.sim.reactions.before_tick(self.sim)
