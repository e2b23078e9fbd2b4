"""What a trigger's actions do to a simulation: start a clip now, switch a constraint on or off,
and the checks that every trigger and target track names what the simulation has."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.components import QueuedClip
from ecs_anim.core.errors import EcsAnimError, listed, quoted
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.playback_queue import start_next_clips
from ecs_anim.runtime.store import MAX_QUEUE
from ecs_anim.runtime.triggers import (
    FEET,
    Action,
    AtTime,
    Condition,
    ContactBegan,
    MoveTarget,
    Near,
    Play,
    Reached,
    SwitchOn,
    TargetTrack,
    Trigger,
    constraints_named,
    entities_named,
)

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

F64 = NDArray[np.float64]


def interpolate_keyframes(times_s: F64, points_m: F64, time_s: float) -> F64:
    """Points (k, 3) at ``time_s`` of k keyframed tracks: ``times_s`` (k, m) increasing (padded
    with inf), ``points_m`` (k, m, 3); linear between keyframes, held outside them."""
    k = times_s.shape[0]
    after = np.clip(np.sum(times_s <= time_s, axis=1), 1, times_s.shape[1] - 1) \
        if times_s.shape[1] > 1 else np.zeros(k, np.int64)
    if times_s.shape[1] == 1:
        return points_m[:, 0].copy()
    before = after - 1
    ks = np.arange(k)
    t0, t1 = times_s[ks, before], times_s[ks, after]
    span = np.where(np.isfinite(t1), t1 - t0, 1.0)
    u = np.where(np.isfinite(t1), np.clip((time_s - t0) / np.maximum(span, 1e-12), 0.0, 1.0), 0.0)
    u = np.where(time_s <= times_s[:, 0], 0.0, u)
    result: F64 = points_m[ks, before] + u[:, None] * (points_m[ks, after] - points_m[ks, before])
    return result


def play_now(sim: Simulation, action: Play) -> None:
    """Start ``action.clip`` on its character now (between ticks), cross-faded, from
    ``action.from_s`` into the clip, followed by ``action.then`` (the rest of its queue is
    replaced). Writes the store's queue, then :func:`start_next_clips` for that row."""
    st, bank = sim.store, sim.bank
    row = sim.row(action.entity)
    clips = [QueuedClip(action.clip, action.crossfade_s, action.loop), *action.then]
    if len(clips) > MAX_QUEUE:
        raise EcsAnimError(f"play {quoted(action.clip)}: at most {MAX_QUEUE - 1} clips after it")
    try:
        indices = [bank.index(q.clip) for q in clips]
    except KeyError as exc:
        raise EcsAnimError(str(exc.args[0])) from None
    st.queue_clip[row, :len(clips)] = indices
    st.queue_fade_s[row, :len(clips)] = [max(q.crossfade_s, 0.0) for q in clips]
    st.queue_loop[row, :len(clips)] = [q.loop for q in clips]
    st.queue_head[row], st.queue_len[row] = 0, len(clips)
    rows = np.array([row], np.int64)
    start_next_clips(st, bank, rows, np.array([max(action.from_s, 0.0)]))


def switch_on(sim: Simulation, uid: int, now_s: float, for_s: float | None) -> None:
    """The constraint's activation from ``now_s``, in simulation time, with its own eases:
    (now, now + for_s (None: for good), ease in, ease out); the shortest ``for_s`` is the two
    eases."""
    table = sim.constraints
    row = _constraint_row(sim, uid)
    ease_in, ease_out = table.activation[row, 2], table.activation[row, 3]
    length = 1e9 if for_s is None else max(for_s, ease_in + ease_out)
    start = now_s
    if table.clock[row] < 0 and table.weight[row] > 0.0:  # on already: it stays on, longer
        start = min(float(table.activation[row, 0]), now_s)
    table.activation[row] = (start, now_s + length, ease_in, ease_out)
    table.clock[row] = -1


def switch_off(sim: Simulation, uid: int, now_s: float) -> None:
    """Ease the constraint out from ``now_s`` over its own ease-out (simulation time)."""
    table = sim.constraints
    row = _constraint_row(sim, uid)
    start, stop, _, ease_out = table.activation[row]
    if table.clock[row] >= 0 or start > now_s:  # not begun (or on a clip's clock): off now
        table.activation[row] = (now_s - 1.0, now_s - 1.0, 0.0, 0.0)
    else:
        table.activation[row, 1] = min(stop, now_s + ease_out)
    table.clock[row] = -1


def switched_off(ease_in_s: float, ease_out_s: float) -> Activation:
    """The activation of a constraint off until a trigger switches it on (:class:`SwitchOn`):
    it ended before the simulation began; its eases are those the switch uses."""
    return Activation(-1.0 - ease_in_s - ease_out_s, -1.0, ease_in_s, ease_out_s)


def _constraint_row(sim: Simulation, uid: int) -> int:
    try:
        return int(sim.constraints.rows_of(np.array([uid]))[0])
    except ValueError as exc:
        raise EcsAnimError(str(exc)) from None


def check_trigger(sim: Simulation, trigger: Trigger) -> None:
    """Raise EcsAnimError naming the trigger if anything it names is not in ``sim`` (a
    character, a constraint id, a clip) or a number is out of range. At the boundary, not in
    the tick."""
    def fail(message: str) -> EcsAnimError:
        return EcsAnimError(f"trigger {quoted(trigger.name)}: {message}")

    if not (np.isfinite(trigger.delay_s) and trigger.delay_s >= 0.0):
        raise fail(f"delay_s must be a number of seconds >= 0, got {trigger.delay_s}")
    if not trigger.then:
        raise fail("no actions (then)")
    items: list[Condition | Action] = [trigger.when, *trigger.then]
    for item in items:
        for entity in entities_named(item):
            try:
                sim.row(entity)
            except EcsAnimError as exc:
                raise fail(str(exc)) from None
        for uid in constraints_named(item):
            try:
                _constraint_row(sim, uid)
            except EcsAnimError as exc:
                raise fail(str(exc)) from None
        for clip in [getattr(item, "clip", None)] + [q.clip for q in getattr(item, "then", ())]:
            if clip is not None and clip not in sim.motions:
                raise fail(f"unknown motion {quoted(clip)} (motions: {listed(sim.motions)})")
    w = trigger.when
    if isinstance(w, (Near, Reached)) and not (np.isfinite(w.within_m) and w.within_m >= 0.0):
        raise fail(f"within_m must be a distance >= 0, got {w.within_m}")
    if isinstance(w, AtTime) and not np.isfinite(w.time_s):
        raise fail(f"the time must be finite, got {w.time_s}")
    if isinstance(w, ContactBegan) and w.foot not in (None, *FEET):
        raise fail(f"foot must be one of {', '.join(FEET)} (or None: either), got {w.foot!r}")
    for a in trigger.then:
        if isinstance(a, Play) and not all(np.isfinite(v) and v >= 0 for v in (a.crossfade_s, a.from_s)):
            raise fail("crossfade_s and from_s must be >= 0")
        if isinstance(a, SwitchOn) and a.for_s is not None and not (np.isfinite(a.for_s) and a.for_s > 0):
            raise fail(f"for_s must be a duration > 0, got {a.for_s}")
        if isinstance(a, MoveTarget) and not all(np.isfinite(a.target_in_world)):
            raise fail("the target must be finite")
    if trigger.name in sim.reactions.by_name:
        raise fail("another trigger has this name (Arm names triggers)")


def check_track(sim: Simulation, track: TargetTrack) -> None:
    """Raise EcsAnimError if a moving target's keyframes are malformed or its constraint is
    not in ``sim``."""
    where = f"moving target of constraint id {track.uid}"
    if not track.times_s or len(track.times_s) != len(track.points_m):
        raise EcsAnimError(f"{where}: give one point (x, y, z) per keyframe time, at least one")
    times = np.array(track.times_s)
    if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)):
        raise EcsAnimError(f"{where}: keyframe times must be finite and increasing, got "
                           f"{listed(f'{t:g}' for t in track.times_s)}")
    if not np.all(np.isfinite(np.array(track.points_m))):
        raise EcsAnimError(f"{where}: keyframe points must be finite")
    _constraint_row(sim, track.uid)
