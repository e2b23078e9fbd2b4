"""MotionPlayback: sample each character's clip(s) in normalized space, then advance the clocks.

Rows: characters with a MotionPlayer.
Reads: store.clip, clip_time_s, speed, loop, fade_*, queue_*, placement_*, fade_placement_*,
lengths (leg length: the root path's unit); the clip bank.
Writes: store.poses (placed in the world; first writer each tick), store.contact_weight,
store.clip_time_s, fade_time_s, fade_elapsed_s, fade_s; on a clip change (through
:func:`ecs_anim.playback_queue.start_next_clips`) clip, loop, queue_head, placement_*, fade_*,
locked.
"""

from __future__ import annotations

import numpy as np
from ecs_anim.components import MotionPlayer

from ecs_anim.playback import blend, rotate_xy, sample, sample_table
from ecs_anim.system_base import System


class MotionPlayback(System):
    query = (MotionPlayer,)
    reads = ("clip", "clip_time_s", "speed", "loop", "fade_clip", "fade_time_s", "fade_loop",
             "fade_s", "fade_elapsed_s", "queue_clip", "queue_fade_s", "queue_loop", "queue_head",
             "queue_len", "placement_xy", "placement_heading", "fade_placement_xy",
             "fade_placement_heading", "lengths")
    writes = ("poses", "contact_weight", "clip_time_s", "fade_time_s", "fade_elapsed_s", "fade_s",
              "clip", "loop", "queue_head", "placement_xy", "placement_heading",
              "fade_placement_xy", "fade_placement_heading", "fade_clip", "fade_loop", "locked")

    def run(self, dt: float) -> None:
        st, bank = self.sim.store, self.sim.bank
        self._start_queued_clips()
        poses = self._placed(sample(bank, st.clip, st.clip_time_s, st.loop),
                             st.placement_xy, st.placement_heading)
        weights = sample_table(bank, bank.contact_weight, st.clip, st.clip_time_s, st.loop)
        fading = st.fade_s > 0.0
        # While two clips blend, their feet are in neither clip's footprints: no foot is locked
        # (feet follow the blend, kept above the ground). Footprints resume with the incoming
        # clip's own contacts once the fade is over.
        weights = np.where(fading[:, None], 0.0, weights)
        if np.any(fading):
            old = self._placed(sample(bank, st.fade_clip, st.fade_time_s, st.fade_loop),
                               st.fade_placement_xy, st.fade_placement_heading)
            w = np.where(fading, np.clip(st.fade_elapsed_s / np.maximum(st.fade_s, 1e-9), 0, 1), 1.0)
            poses = blend(old, poses, w)
            st.fade_s = np.where(w >= 1.0, 0.0, st.fade_s)
        st.poses = poses
        st.contact_weight = weights
        step = dt * st.speed
        st.clip_time_s += step
        st.fade_time_s += step
        st.fade_elapsed_s += dt

    def _placed(self, poses, xy, heading):  # type: ignore[no-untyped-def]
        """Lay each motion out from its placement (``xy`` (n, 2) m, ``heading`` (n,) rad):
        rotate the root path about the motion origin, then shift it."""
        leg = self.sim.leg_length()
        root = poses.root_position.copy()
        root[:, :2] = (rotate_xy(root[:, :2] * leg[:, None], heading) + xy) / leg[:, None]
        poses.root_position = root
        poses.root_heading = poses.root_heading + heading
        return poses

    def _start_queued_clips(self) -> None:
        """Start the next queued clip ``crossfade_s`` before the current one ends (not while a
        cross-fade is still running), for all characters due at once."""
        st, bank = self.sim.store, self.sim.bank
        pending = st.queue_head < st.queue_len
        if not pending.any():
            return
        head = np.minimum(st.queue_head, st.queue_clip.shape[1] - 1)
        next_fade = st.queue_fade_s[np.arange(st.n), head]
        due = pending & (st.fade_s == 0.0) & (st.clip_time_s >= bank.duration_s(st.clip) - next_fade)
        if due.any():
            self.sim.start_next_clips(np.flatnonzero(due))
