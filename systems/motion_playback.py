"""MotionPlayback: advance each character's clock and sample its clip(s) in normalized space.

Reads: store.clip, clip_time_s, speed, loop, fade_*, queue_len, next_fade_s, placement_*,
fade_placement_*; the clip bank.
Writes: store.clip_time_s, fade_*, clip/loop/queue/placement on a clip change (its only writer),
store.poses (placed in the world; first writer each tick), store.contact_weight.
"""

from __future__ import annotations

import numpy as np

from ecs_anim.playback import blend, sample, sample_table
from ecs_anim.system_base import System


def _rotate(xy: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], axis=-1)


class MotionPlayback(System):
    def run(self, dt: float) -> None:
        st, bank = self.sim.store, self.sim.bank
        step = dt * st.speed
        st.clip_time_s += step
        st.fade_time_s += step
        st.fade_elapsed_s += dt
        self._start_queued_clips()
        poses = self._placed(sample(bank, st.clip, st.clip_time_s, st.loop),
                             st.placement_xy, st.placement_heading)
        weights = sample_table(bank, bank.contact_weight, st.clip, st.clip_time_s, st.loop)
        fading = st.fade_s > 0.0
        if np.any(fading):
            old = self._placed(sample(bank, st.fade_clip, st.fade_time_s, st.fade_loop),
                               st.fade_placement_xy, st.fade_placement_heading)
            w = np.where(fading, np.clip(st.fade_elapsed_s / np.maximum(st.fade_s, 1e-9), 0, 1), 1.0)
            poses = blend(old, poses, w)
            old_w = sample_table(bank, bank.contact_weight, st.fade_clip, st.fade_time_s, st.fade_loop)
            weights = old_w + w[:, None] * (weights - old_w)
            st.fade_s = np.where(w >= 1.0, 0.0, st.fade_s)
        st.poses = poses
        st.contact_weight = weights

    def _placed(self, poses, xy, heading):  # type: ignore[no-untyped-def]
        """Lay each motion out from its placement (``xy`` (n, 2) m, ``heading`` (n,) rad):
        rotate the root path about the motion origin, then shift it."""
        leg = self.sim.leg_length()
        root = poses.root_position.copy()
        root[:, :2] = (_rotate(root[:, :2] * leg[:, None], heading) + xy) / leg[:, None]
        poses.root_position = root
        poses.root_heading = poses.root_heading + heading
        return poses

    def _start_queued_clips(self) -> None:
        """Start the next queued clip where the current one is about to end (an event: only the
        characters changing clip are visited)."""
        st, bank = self.sim.store, self.sim.bank
        due = (st.queue_len > 0) & (st.clip_time_s >= bank.duration_s(st.clip) - st.next_fade_s)
        for row in np.flatnonzero(due):
            self.sim.start_next_clip(int(row))
