"""Starting a character's next queued clip: the cross-fade bookkeeping of MotionPlayback.

A rare path (a clip change), so numpy over the characters due this tick, not a kernel. Pure
functions of the store: MotionPlayback decides who is due and calls :func:`start_next_clips`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import leg_length
from ecs_anim.motion.sampling import ClipBank, rotate_xy, sample_root, wrap_angle
from ecs_anim.runtime.store import CharacterStore


def start_next_clips(st: CharacterStore, bank: ClipBank, rows: NDArray[np.int64],
                     start_s: NDArray[np.float64] | None = None) -> None:
    """Begin the next queued clip of the characters in ``rows`` (r,) (all at once),
    cross-fading from the current one and continuing its root path, heading included, at
    ``start_s`` (r,) seconds into it (None: at its start; a trigger's ``Play.from_s``).
    Footprints are released so the incoming motion's steps lay new ones.

    Reads store.queue_*; writes queue_head and, through :func:`start_clips`, the clip, fade and
    placement fields and locked.
    """
    head = st.queue_head[rows]
    start_clips(st, bank, rows, st.queue_clip[rows, head],
                np.zeros(rows.size) if start_s is None else start_s,
                st.queue_fade_s[rows, head], st.queue_loop[rows, head])
    st.queue_head[rows] += 1


def start_clips(st: CharacterStore, bank: ClipBank, rows: NDArray[np.int64],
                new_clip: NDArray[np.int64], new_time_s: NDArray[np.float64],
                fade_s: NDArray[np.float64], new_loop: NDArray[np.bool_],
                keep_contacts: bool = False) -> None:
    """Cross-fade the characters in ``rows`` (r,) from their clip to ``new_clip`` (r,) started
    at ``new_time_s`` (r,) seconds of it, over ``fade_s`` (r,) seconds, continuing the root path
    (the new clip's root placed where the old one's is, with its heading).

    ``keep_contacts``: a foot down in both clips keeps its footprint through the fade (clips
    switched at matching foot phases, as locomotion does); otherwise footprints are released and
    no foot is locked while the clips blend.

    Reads store.clip, clip_time_s, loop, lengths, placement_*; writes fade_* (the outgoing clip,
    its placement and rate), fade_keeps_contacts, clip, clip_time_s, loop, placement_*, locked.
    """
    # The outgoing and the incoming clips' roots in one call (a trigger starts one clip).
    root_xy, root_heading = sample_root(
        bank, np.concatenate([st.clip[rows], new_clip]),
        np.concatenate([st.clip_time_s[rows], new_time_s]),
        np.concatenate([st.loop[rows], new_loop]))
    r = rows.size
    old_root_xy, old_root_heading = root_xy[:r], root_heading[:r]
    new_root_xy, new_root_heading = root_xy[r:], root_heading[r:]
    leg = leg_length(st.lengths[rows])[:, None]
    heading = st.placement_heading[rows]
    old_xy = rotate_xy(old_root_xy * leg, heading) + st.placement_xy[rows]
    new_heading = wrap_angle(old_root_heading + heading - new_root_heading)
    st.fade_placement_xy[rows] = st.placement_xy[rows]
    st.fade_placement_heading[rows] = heading
    st.placement_heading[rows] = new_heading
    st.placement_xy[rows] = old_xy - rotate_xy(new_root_xy * leg, new_heading)
    st.fade_clip[rows], st.fade_time_s[rows] = st.clip[rows], st.clip_time_s[rows]
    st.fade_loop[rows] = st.loop[rows]
    st.fade_s[rows], st.fade_elapsed_s[rows] = np.maximum(fade_s, 0.0), 0.0
    st.fade_keeps_contacts[rows] = keep_contacts
    st.fade_speed[rows] = st.speed[rows]
    st.clip[rows], st.clip_time_s[rows], st.loop[rows] = new_clip, new_time_s, new_loop
    if not keep_contacts:
        st.locked[rows] = False
