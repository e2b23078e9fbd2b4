"""Starting a character's next queued clip: the cross-fade bookkeeping of MotionPlayback.

A rare path (a clip change), so numpy over the characters due this tick, not a kernel. Pure
functions of the store: MotionPlayback decides who is due and calls :func:`start_next_clips`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .morphology import leg_length
from .playback import ClipBank, _wrap, rotate_xy, sample
from .store import CharacterStore


def start_next_clips(st: CharacterStore, bank: ClipBank, rows: NDArray[np.int64],
                     start_s: NDArray[np.float64] | None = None) -> None:
    """Begin the next queued clip of the characters in ``rows`` (r,) (all at once),
    cross-fading from the current one and continuing its root path, heading included, at
    ``start_s`` (r,) seconds into it (None: at its start; a trigger's ``Play.from_s``).
    Footprints are released so the incoming motion's steps lay new ones.

    Reads store.clip, clip_time_s, loop, queue_*, lengths, placement_*; writes fade_* (the
    outgoing clip and its placement), clip, clip_time_s, loop, placement_*, queue_head, locked.
    """
    head = st.queue_head[rows]
    new_clip, fade = st.queue_clip[rows, head], st.queue_fade_s[rows, head]
    new_loop = st.queue_loop[rows, head]
    old = sample(bank, st.clip[rows], st.clip_time_s[rows], st.loop[rows])
    start = np.zeros(rows.size) if start_s is None else start_s
    new = sample(bank, new_clip, start, new_loop)
    leg = leg_length(st.lengths[rows])[:, None]
    heading = st.placement_heading[rows]
    old_xy = rotate_xy(old.root_position[:, :2] * leg, heading) + st.placement_xy[rows]
    new_heading = _wrap(old.root_heading + heading - new.root_heading)
    st.fade_placement_xy[rows] = st.placement_xy[rows]
    st.fade_placement_heading[rows] = heading
    st.placement_heading[rows] = new_heading
    st.placement_xy[rows] = old_xy - rotate_xy(new.root_position[:, :2] * leg, new_heading)
    st.fade_clip[rows], st.fade_time_s[rows] = st.clip[rows], st.clip_time_s[rows]
    st.fade_loop[rows] = st.loop[rows]
    st.fade_s[rows], st.fade_elapsed_s[rows] = np.maximum(fade, 0.0), 0.0
    st.clip[rows], st.clip_time_s[rows], st.loop[rows] = new_clip, start, new_loop
    st.queue_head[rows] += 1
    st.locked[rows] = False
