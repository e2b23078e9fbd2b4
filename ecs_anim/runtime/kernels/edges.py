"""The clip and contact edges of a tick (``ecs_anim.runtime.events.Reactions.after_tick``), compiled over
the characters: mirrors :func:`ecs_anim.runtime.events.clip_and_contact_edges`, the numpy reference.

One pass over the store's rows that reads and updates what the last tick left per entity id:
about 10 µs for 6,400 characters where the numpy one, a dozen gathers and scatters by entity,
took 0.3 ms (the tick's largest piece of Python on one thread in an unconstrained crowd). It is
called directly, not over threads: a hand-over would cost more than the pass."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels.vec import F64, jit

I64 = NDArray[np.int64]
B = NDArray[np.bool_]


@jit(nogil=True)
def edge_rows(lo: int, hi: int, entity: I64, clip: I64, clip_time_s: F64, speed: F64, loop: B,
              duration_s: F64, contact_weight: F64, dt: float, slack_s: float,
              began_weight: float, seen_clip: I64, seen_time_s: F64, seen_ended: B,
              seen_below: B, listed: I64, counts: I64) -> None:
    """Rows ``lo..hi-1`` of :func:`ecs_anim.runtime.events.clip_and_contact_edges`, the
    ``seen_*`` arrays (by entity id) updated and the edges listed (what the caller reads: no
    (n, 5) edges nor (n,) clips seen before written, which nothing read), in the order of the
    rows: ``listed[k, :counts[k]]`` the rows of edge column ``k`` < 3, ``listed[3, :counts[3]]``
    ``2 * row + foot`` of each contact begun, ``listed[4, :counts[0]]`` the clip seen before by
    each row of ``listed[0]`` (``listed`` (5, 2 n), ``counts`` (4,) written; called over all
    rows at once)."""
    # The counts and each row's values in locals: written to arrays and read back, every
    # store might alias them (a quarter of the pass's time).
    replaced_count = ended_count = started_count = began_count = 0
    for r in range(lo, hi):
        e, row_clip, time_s = entity[r], clip[r], clip_time_s[r]
        old_clip = seen_clip[e]
        ended = seen_ended[e]
        new_clip = row_clip != old_clip or time_s < seen_time_s[e] - slack_s
        sampled = time_s - dt * speed[r]
        at_end = not loop[r] and sampled >= duration_s[row_clip] - slack_s
        if new_clip and old_clip >= 0 and not ended:  # replaced
            listed[0, replaced_count] = r
            listed[4, replaced_count] = old_clip
            replaced_count += 1
        if not new_clip and at_end and not ended:  # ended now
            listed[1, ended_count] = r
            ended_count += 1
        if new_clip:
            listed[2, started_count] = r
            started_count += 1
        for foot in range(2):
            weight = contact_weight[r, foot]
            began = weight >= began_weight and seen_below[e, foot]
            seen_below[e, foot] = weight < began_weight
            if began:
                listed[3, began_count] = 2 * r + foot
                began_count += 1
        seen_ended[e] = not new_clip and (ended or at_end)
        seen_clip[e] = row_clip
        seen_time_s[e] = time_s
    counts[0], counts[1], counts[2], counts[3] = (replaced_count, ended_count, started_count,
                                                  began_count)


class EdgeScratch:
    """The arrays :func:`clip_and_contact_edges` writes, kept from tick to tick (the lists
    are ``(5, 2 n)`` int64: 320 KB at 4,000 characters, fresh pages every tick when allocated
    anew)."""

    def __init__(self) -> None:
        self.listed = np.empty((5, 0), np.int64)
        self.counts = np.empty(4, np.int64)

    def fit(self, n: int) -> EdgeScratch:
        """These arrays for ``n`` rows (made anew when the rows change)."""
        if self.listed.shape[1] != 2 * n:
            self.listed = np.empty((5, 2 * n), np.int64)
        return self


def clip_and_contact_edges(entity: I64, clip: I64, clip_time_s: F64, speed: F64, loop: B,
                           duration_s: F64, contact_weight: F64, dt: float, slack_s: float,
                           began_weight: float, seen_clip: I64, seen_time_s: F64, seen_ended: B,
                           seen_below: B, *, scratch: EdgeScratch | None = None
                           ) -> tuple[list[I64], I64]:
    """:func:`ecs_anim.runtime.events.clip_and_contact_edges`, compiled (same arguments; the
    ``seen_*`` arrays updated alike), its edges listed
    (:func:`ecs_anim.runtime.events.edges_listed`: the rows of each of the first three
    columns, and ``2 * row + foot`` of the contacts begun, each in the order of the rows) and
    the clip seen before by each row of the first list (the clip replaced), each its own array.
    ``scratch``: the arrays to write (new if None)."""
    n = entity.shape[0]
    out = (EdgeScratch() if scratch is None else scratch).fit(n)
    edge_rows(0, n, entity, clip, clip_time_s, speed, loop, duration_s, contact_weight, dt,
              slack_s, began_weight, seen_clip, seen_time_s, seen_ended, seen_below,
              out.listed, out.counts)
    counts = out.counts.tolist()
    listed = [out.listed[k, :counts[k]].copy() for k in range(4)]
    return listed, out.listed[4, :counts[0]].copy()
