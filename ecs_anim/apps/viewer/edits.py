"""What the viewer changes in a running simulation, and the log that replays it.

Every change made from the window (a body grown or shrunk, a target moved, a character added
or removed) is an :class:`Edit` at the tick it was made, naming characters and constraints by
name. The log replays them at the same ticks when the viewer re-simulates (scrubbing back,
looping, restarting, reloading the YAML), so a rebuilt simulation reaches the same state; an
edit that no longer applies (its character is gone from the reloaded file) is dropped with a
message. Pure Python and numpy: no pyglet here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import esper
import numpy as np

from ecs_anim.components import MotionPlayer, Name, Placement, QueuedClip
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import MAX_STATURE_M, MIN_STATURE_M, Morphology
from ecs_anim.runtime.simulation import Simulation

#: A copy stands this far to the left of the character it copies (metres, across its heading).
COPY_SIDE_M = 1.0
#: A stature key's change blends in over this long (s), so that the feet stay planted and no
#: joint jumps (Simulation.set_body's blend).
STATURE_BLEND_S = 0.25


def scaled_body(body: Morphology, factor: float) -> Morphology:
    """``body`` with every length times ``factor`` (so its stature too) and its mass times
    ``factor``² (the same body-mass index, as :meth:`Morphology.from_stature` keeps)."""
    stature = body.stature * factor
    if not MIN_STATURE_M <= stature <= MAX_STATURE_M:
        raise EcsAnimError(f"a stature of {stature:.2f} m is outside {MIN_STATURE_M:g}-"
                           f"{MAX_STATURE_M:g} m")
    return Morphology(body.lengths * factor, body.mass_kg * factor**2, body.sex, body.name)


def spawn_copy(sim: Simulation, entity: int, name: str) -> int:
    """Add a character called ``name`` with ``entity``'s body, team, ground and centre-of-mass
    control, playing its clip in step with it (same clip time, speed, loop and the clips still
    queued), placed :data:`COPY_SIDE_M` to its left. Its motion's own stored constraints come
    with the clip; the scenario's constraints on the original (and a desired centre of mass
    given as a point) do not. Returns the new entity."""
    row, st = sim.row(entity), sim.store
    with sim._active():
        team = esper.component_for_entity(entity, Name).team
    bank = sim.bank.names
    head, end = int(st.queue_head[row]), int(st.queue_len[row])
    queue = tuple(QueuedClip(bank[int(st.queue_clip[row, j])], float(st.queue_fade_s[row, j]),
                             bool(st.queue_loop[row, j])) for j in range(head, end))
    # MotionPlayback samples and then advances the clock: clip_time_s is the next tick's time,
    # where the copy's first tick samples too.
    player = MotionPlayer(bank[int(st.clip[row])], float(st.speed[row]), bool(st.loop[row]),
                          float(st.clip_time_s[row]), queue)
    heading = float(st.placement_heading[row])
    left = np.array([-math.sin(heading), math.cos(heading)])
    xy = st.placement_xy[row] + COPY_SIDE_M * left
    ground = int(st.ground_index[row])
    return sim.spawn(name, sim.body(entity), player,
                     Placement((float(xy[0]), float(xy[1])), heading), team,
                     com_control=bool(st.com_control[row]),
                     ground=sim.grounds[ground] if ground else None)


def copy_name(sim: Simulation, name: str) -> str:
    """A name for a copy of ``name`` that no character has: ``name_2``, ``name_3``, ..."""
    taken = set(sim.names())
    k = 2
    while f"{name}_{k}" in taken:
        k += 1
    return f"{name}_{k}"


@dataclass(frozen=True)
class Edit:
    """One change made from the viewer, applied between ticks before tick ``tick`` is stepped.

    kind: ``"scale"`` (``value`` the stature factor), ``"target"`` (``value`` (constraint
    name, (x, y, z) world metres)), ``"copy"`` (``value`` the new character's name) or
    ``"remove"``; ``character``: the character's name.
    """

    tick: int
    kind: str
    character: str
    value: Any = None


def apply_edit(sim: Simulation, edit: Edit) -> int | None:
    """Make ``edit``'s change in ``sim`` now; returns the new entity for a copy. Errors (a
    character or constraint that is not there, a stature out of range) are EcsAnimError."""
    entity = sim.entity(edit.character)
    if edit.kind == "scale":
        sim.set_body(entity, scaled_body(sim.body(entity), float(edit.value)),
                     blend_s=STATURE_BLEND_S)
    elif edit.kind == "target":
        constraint, target_in_world = edit.value
        sim.set_target(sim.constraint_index(entity, constraint), target_in_world)
    elif edit.kind == "copy":
        return spawn_copy(sim, entity, str(edit.value))
    elif edit.kind == "remove":
        sim.remove(entity)
    else:  # pragma: no cover - the viewer makes only the kinds above
        raise ValueError(f"unknown edit kind {edit.kind!r}")
    return None


@dataclass
class EditLog:
    """The viewer's edits by tick, in the order they were made."""

    by_tick: dict[int, list[Edit]] = field(default_factory=dict)

    def __len__(self) -> int:
        return sum(len(edits) for edits in self.by_tick.values())

    def record(self, edit: Edit) -> None:
        """Add ``edit``; a target moved again in the same tick replaces the earlier move (a
        drag makes one edit per tick, not one per mouse event)."""
        edits = self.by_tick.setdefault(edit.tick, [])
        if (edit.kind == "target" and edits and edits[-1].kind == "target"
                and edits[-1].character == edit.character and edits[-1].value[0] == edit.value[0]):
            edits[-1] = edit
        else:
            edits.append(edit)

    def replay(self, sim: Simulation, skip: Sequence[Edit] = ()) -> list[str]:
        """Apply the edits of tick ``sim.tick`` (call before stepping it) but those in ``skip``
        (made live on this simulation already); those that fail are dropped from the log, and
        their one-line messages returned."""
        problems = []
        for edit in list(self.by_tick.get(sim.tick, ())):
            if any(edit is done for done in skip):
                continue
            try:
                apply_edit(sim, edit)
            except EcsAnimError as exc:
                self.by_tick[sim.tick].remove(edit)
                problems.append(f"edit at t={sim.time_s:.2f} s dropped: {exc}")
        return problems
