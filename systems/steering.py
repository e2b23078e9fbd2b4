"""Steering: steered characters' heading, speed and locomotion clip for this tick.

Paths, goals, or a heading and speed given each tick (``docs/steering.md``); all steered
characters at once (:func:`ecs_anim.runtime.steering.steer`): path progress, the heading and
speed wanted, the clip of the locomotion set to play (a cross-fade started at matching foot
phases), the playback rate, and the turn of the placement about the planted foot.

Rows: characters with a MotionPlayer (only those with ``steer_mode`` set are steered).
Reads: store.steer_mode, steer_heading_rad, steer_speed_m_s, path_xy, path_len, path_cum_m,
path_progress_m, gait, gait_clip, clip, clip_time_s, loop, speed, fade_s, fade_elapsed_s,
fade_keeps_contacts, fade_clip, fade_time_s, fade_loop, fade_placement_xy,
fade_placement_heading, placement_xy, placement_heading, lengths, and the last tick's
contact_weight, locked, footprint; entity (against the entities switched off by
``Simulation.set_avoidance``); the clip bank.
Writes: steer_mode, steer_heading_rad, steer_speed_m_s (a path's end: stopped),
path_progress_m, gait, speed (the playback rate, after local avoidance: ORCA between the
steered characters), and starting a gait's clip: clip,
clip_time_s, loop, fade_clip, fade_time_s, fade_loop, fade_s, fade_elapsed_s,
fade_keeps_contacts, fade_speed, placement_xy, placement_heading, fade_placement_xy,
fade_placement_heading, locked.
"""

from __future__ import annotations

from ecs_anim.components import MotionPlayer
from ecs_anim.runtime.steering import steer
from ecs_anim.runtime.system_base import System
from ecs_anim.systems.queued_clips import CLIP_START_WRITES


class Steering(System):
    query = (MotionPlayer,)
    reads = ("steer_mode", "steer_heading_rad", "steer_speed_m_s", "path_xy", "path_len",
             "path_cum_m", "path_progress_m", "gait", "gait_clip", "clip", "clip_time_s", "loop",
             "speed", "fade_s", "fade_elapsed_s", "fade_keeps_contacts", "fade_clip",
             "fade_time_s", "fade_loop", "fade_placement_xy", "fade_placement_heading",
             "placement_xy", "placement_heading", "lengths", "contact_weight", "locked",
             "footprint", "entity")
    writes = ("steer_mode", "steer_heading_rad", "steer_speed_m_s", "path_progress_m", "gait",
              "speed", *CLIP_START_WRITES)

    def run(self, dt: float) -> None:
        sim = self.sim
        steer(sim.store, sim.bank, sim.gait_table(), sim.steering_settings, dt,
              None if self.all_rows() else self.in_rows(), sim.not_avoiding())
