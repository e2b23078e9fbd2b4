"""QueuedClips: a character's next queued clip starts, cross-faded, as the current one ends.

Rows: characters with a MotionPlayer.
Reads: store.queue_clip, queue_fade_s, queue_loop, queue_head, queue_len, fade_s, clip,
clip_time_s, loop, speed, lengths, placement_xy, placement_heading; the clip bank.
Writes: (through :func:`ecs_anim.runtime.playback_queue.start_next_clips`, for the characters
due this tick, all at once) queue_head, clip, clip_time_s, loop, fade_clip, fade_time_s,
fade_loop, fade_s, fade_elapsed_s, fade_keeps_contacts, fade_speed, placement_xy,
placement_heading, fade_placement_xy, fade_placement_heading, locked.
"""

from __future__ import annotations

import numpy as np

from ecs_anim.components import MotionPlayer
from ecs_anim.runtime.playback_queue import start_next_clips
from ecs_anim.runtime.system_base import System

#: What starting a clip writes (:func:`ecs_anim.runtime.playback_queue.start_clips`).
CLIP_START_WRITES = ("clip", "clip_time_s", "loop", "fade_clip", "fade_time_s", "fade_loop",
                     "fade_s", "fade_elapsed_s", "fade_keeps_contacts", "fade_speed",
                     "placement_xy", "placement_heading", "fade_placement_xy",
                     "fade_placement_heading", "locked")


class QueuedClips(System):
    query = (MotionPlayer,)
    reads = ("queue_clip", "queue_fade_s", "queue_loop", "queue_head", "queue_len", "fade_s",
             "clip", "clip_time_s", "loop", "speed", "lengths", "placement_xy",
             "placement_heading")
    writes = ("queue_head", *CLIP_START_WRITES)

    def run(self, dt: float) -> None:
        """Start the next queued clip ``crossfade_s`` before the current one ends (not while a
        cross-fade is still running), for all characters due at once."""
        st, bank = self.sim.store, self.sim.bank
        pending = st.queue_head < st.queue_len
        if not pending.any():
            return
        head = np.minimum(st.queue_head, st.queue_clip.shape[1] - 1)
        next_fade = st.queue_fade_s[np.arange(st.n), head]
        due = pending & (st.fade_s == 0.0) & (st.clip_time_s >= bank.duration_s(st.clip) - next_fade)
        if not self.all_rows():
            due &= self.in_rows()
        if due.any():
            start_next_clips(st, bank, np.flatnonzero(due))
