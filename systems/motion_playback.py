"""MotionPlayback: sample each character's clip(s) in normalized space, advance the clocks.

Each clip's root height is played relative to the ground its capture stood on
(:attr:`~ecs_anim.motion.clip.NormalizedMotion.capture_ground`); GroundAdapt puts the
character's own ground under it.

The clip each plays was chosen before it this tick (QueuedClips, Steering, ApplyReactions).

Rows: characters with a MotionPlayer; under a frame budget that cannot hold otherwise, those
due this tick (:mod:`ecs_anim.runtime.update_rate`: the others keep their pose, their clocks
run on).
Reads: store.clip, clip_time_s, speed, fade_speed, loop, fade_clip, fade_time_s, fade_loop,
fade_s, fade_elapsed_s, fade_keeps_contacts, placement_*, fade_placement_*, lengths (leg
length: the root path's unit), the last tick's contact_weight (through a cross-fade); the clip
bank.
Writes: store.poses (placed in the world; first writer each tick), store.contact_weight,
store.sole_roll (the part of each foot the clip plants),
store.clip_time_s, fade_time_s, fade_elapsed_s, fade_s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.components import MotionPlayer
from ecs_anim.core.normalized import NormalizedPoses
from ecs_anim.motion.sampling import ClipBank, blend, rotate_xy, sample, sample_table
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import PoseArrays, pose_arrays
from ecs_anim.runtime.kernels.playback import (
    PlaybackBank,
    PlaybackWork,
    advance_clocks,
    blend_rows,
    empty_poses,
    playback_bank,
    sample_placed,
    writable_poses,
)
from ecs_anim.runtime.system_base import System
from ecs_anim.solver.shell import scatter

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation


class MotionPlayback(System):
    """Samples with the compiled :mod:`ecs_anim.runtime.kernels.playback` (numpy reference:
    :meth:`run_numpy`, which runs while the kernels compile aside), into the store's pose
    arrays in place."""

    query = (MotionPlayer,)
    follows_update_rate = True
    reads = ("clip", "clip_time_s", "speed", "fade_speed", "loop", "fade_clip", "fade_time_s",
             "fade_loop", "fade_s", "fade_elapsed_s", "fade_keeps_contacts", "placement_xy",
             "placement_heading", "fade_placement_xy", "fade_placement_heading", "lengths",
             "contact_weight")
    writes = ("poses", "contact_weight", "sole_roll", "clip_time_s", "fade_time_s", "fade_elapsed_s", "fade_s")

    def __init__(self, sim: Simulation):
        super().__init__(sim)
        self._bank: tuple[ClipBank, PlaybackBank] | None = None
        self._work, self._fade_work = PlaybackWork(), PlaybackWork()
        #: The store's pose arrays as the kernels write them, from the last tick (None: none).
        self._out: PoseArrays | None = None

    def run(self, dt: float) -> None:
        if not self.sim.compiled:  # the kernels compile aside (a first run)
            self.run_numpy(dt)
            return
        st = self.sim.store
        release_step = dt / self.sim.steering_settings.contact_release_s
        rows = self.rows()
        playing = self.sim.update_rate.due_rows(self.sim, rows)  # (every clock runs on)
        out = self._pose_arrays()
        bank = self._playback_bank(self.sim.bank)
        if st.contact_weight.shape != (st.n, 2) or not st.contact_weight.flags.writeable:
            st.contact_weight = np.zeros((st.n, 2))
        if not st.sole_roll.flags.writeable:
            st.sole_roll = st.sole_roll.copy()
        fading = playing[st.fade_s[playing] > 0.0]
        fading.setflags(write=False)  # as ``rows``: the samplers' one compiled specialisation
        previous = st.contact_weight[fading]  # the last tick's (a copy)
        sample_placed(bank, playing, st.clip, st.clip_time_s, st.loop, st.placement_xy,
                      st.placement_heading, st.lengths, out, playing, st.contact_weight,
                      st.sole_roll, self._work)
        if fading.size:
            old_weight, old_roll = np.zeros((st.n, 2)), np.zeros((st.n, 2))
            old = pose_arrays(empty_poses(fading.size))
            sample_placed(bank, fading, st.fade_clip, st.fade_time_s, st.fade_loop,
                          st.fade_placement_xy, st.fade_placement_heading, st.lengths, old,
                          self.rows_of_old(fading.size), old_weight, old_roll, self._fade_work)
            st.contact_weight[fading] = self._fading_weights(
                st.contact_weight[fading], old_weight[fading], previous,
                st.fade_keeps_contacts[fading], release_step)
            w = np.clip(st.fade_elapsed_s[fading] / np.maximum(st.fade_s[fading], 1e-9), 0, 1)
            over_chunks(blend_rows, fading.size, fading, old, w, out)
            st.fade_s[fading] = np.where(w >= 1.0, 0.0, st.fade_s[fading])
        # :meth:`_advance_clocks` in one pass (numpy's three made two temporaries)
        advance_clocks(rows, dt, st.speed, st.fade_speed, st.clip_time_s, st.fade_time_s,
                       st.fade_elapsed_s)

    @staticmethod
    def rows_of_old(n: int) -> NDArray[np.int64]:
        """``0..n-1``, read-only as :meth:`rows` (the type the sampler was compiled for)."""
        rows = np.arange(n, dtype=np.int64)
        rows.setflags(write=False)
        return rows

    def run_numpy(self, dt: float) -> None:
        """The numpy reference of :meth:`run` (the tests compare the two)."""
        st, bank = self.sim.store, self.sim.bank
        previous = st.contact_weight.copy()
        poses = self._placed(sample(bank, st.clip, st.clip_time_s, st.loop),
                             st.placement_xy, st.placement_heading)
        poses.root_position[:, 2] -= sample_table(bank, bank.capture_ground, st.clip,
                                                  st.clip_time_s, st.loop)[:, 0]
        weights = sample_table(bank, bank.contact_weight, st.clip, st.clip_time_s, st.loop)
        roll = sample_table(bank, bank.sole_roll, st.clip, st.clip_time_s, st.loop)
        fading = st.fade_s > 0.0
        w = np.where(fading, np.clip(st.fade_elapsed_s / np.maximum(st.fade_s, 1e-9), 0, 1), 1.0)
        old_weights = sample_table(bank, bank.contact_weight, st.fade_clip, st.fade_time_s,
                                   st.fade_loop)
        weights = np.where(fading[:, None],
                           self._fading_weights(weights, old_weights, previous,
                                                st.fade_keeps_contacts,
                                                dt / self.sim.steering_settings.contact_release_s),
                           weights)
        playing = self.in_rows()
        if np.any(fading):
            old = self._placed(sample(bank, st.fade_clip, st.fade_time_s, st.fade_loop),
                               st.fade_placement_xy, st.fade_placement_heading)
            old.root_position[:, 2] -= sample_table(bank, bank.capture_ground, st.fade_clip,
                                                    st.fade_time_s, st.fade_loop)[:, 0]
            poses = blend(old, poses, w)
            st.fade_s = np.where((w >= 1.0) & playing, 0.0, st.fade_s)
        if self.all_rows():
            st.poses, st.contact_weight, st.sole_roll = poses, weights, roll
        else:  # the characters without a MotionPlayer keep their pose and contacts
            rows = self.rows()
            st.poses = scatter(st.poses, rows, poses.take(rows))
            st.contact_weight = np.where(playing[:, None], weights, st.contact_weight)
            st.sole_roll = np.where(playing[:, None], roll, st.sole_roll)
        self._advance_clocks(dt)

    @staticmethod
    def _fading_weights(new: NDArray[np.float64], old: NDArray[np.float64],
                        previous: NDArray[np.float64], keep: NDArray[np.bool_],
                        release_step: float) -> NDArray[np.float64]:
        """Contact weights (r, 2) while two clips blend (``new``, ``old``: each clip's own;
        ``previous``: the last tick's). Clips switched at matching foot phases (``keep``,
        locomotion): a foot down in both stays on its footprint; one that either clip lifts is
        released by at most ``release_step`` a tick (the blended pose's ankle is not where the
        footprint is: an instant release would jump to it). Otherwise their feet are in neither
        clip's footprints: no foot is locked (feet follow the blend, kept above the ground), and
        footprints resume with the incoming clip's own contacts once the fade is over."""
        both = np.minimum(new, old)
        kept = np.where(previous > both, np.maximum(both, previous - release_step), both)
        weights: NDArray[np.float64] = np.where(keep[:, None], kept, 0.0)
        return weights

    def _pose_arrays(self) -> PoseArrays:
        """The store's pose arrays made writable (:func:`writable_poses`) as the kernels take
        them; last tick's while the store holds the same array objects (checking each array's
        shape and flags again was a twentieth of the system's time at 4,000 characters)."""
        st, out = self.sim.store, self._out
        if out is None or out.root_heading.shape[0] != st.n or not all(
                getattr(st.poses, name) is a for name, a in zip(PoseArrays._fields, out,
                                                                strict=True)):
            out = self._out = pose_arrays(writable_poses(st.poses, st.n))
        return out

    def _advance_clocks(self, dt: float) -> None:
        st = self.sim.store
        if self.all_rows():
            st.clip_time_s += dt * st.speed
            st.fade_time_s += dt * st.fade_speed
            st.fade_elapsed_s += dt
            return
        rows = self.rows()
        st.clip_time_s[rows] += dt * st.speed[rows]
        st.fade_time_s[rows] += dt * st.fade_speed[rows]
        st.fade_elapsed_s[rows] += dt

    def _playback_bank(self, bank: ClipBank) -> PlaybackBank:
        """The bank as the kernels read it (made once per bank)."""
        if self._bank is None or self._bank[0] is not bank:
            self._bank = bank, playback_bank(bank)
        return self._bank[1]

    def _placed(self, poses: NormalizedPoses, xy: NDArray[np.float64],
                heading: NDArray[np.float64]) -> NormalizedPoses:
        """Lay each motion out from its placement (``xy`` (n, 2) m, ``heading`` (n,) rad):
        rotate the root path about the motion origin, then shift it."""
        leg = self.sim.leg_length()
        root = poses.root_position.copy()
        root[:, :2] = (rotate_xy(root[:, :2] * leg[:, None], heading) + xy) / leg[:, None]
        poses.root_position = root
        poses.root_heading = poses.root_heading + heading
        return poses
