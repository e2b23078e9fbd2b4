"""A run recorded for export: ``rec = sim.record()`` collects every tick's posture, and
``rec.save(folder)`` writes what ``ecs-anim run --export`` writes (the command uses it).

Each tick (after :meth:`Simulation.step <ecs_anim.runtime.simulation.Simulation.step>`) the
recorder copies the recorded characters' rows of the store: joint positions, the export
skeleton's local rotations, segment lengths (the body each posture was made on) and planted
feet, and keeps the tick's events. Characters are followed by entity, never by row: rows move
down when one is removed, and a removed character keeps what was recorded up to its removal.
Ticks with the same characters in the store form a stretch whose arrays are stacked once, when
they are read; the per-tick work is a few whole-array copies, with a Python loop only over
characters seen for the first time (their names and bodies are read then) and, after a
structural change (a body replaced, a character spawned or removed), over the recorded
characters' bodies.

A body changed while the character played (``set_body``) is exported as it changed: the rest
skeleton of its ``.bvh`` and ``.glb`` is its final body and the offsets that changed are
animated (:mod:`ecs_anim.io.export.bvh`, :mod:`ecs_anim.io.export.gltf`), so every file agrees
with the ``.npz`` on every frame. Saved ``onto=`` a user's rig, every character is retargeted
onto the rig's body (:func:`~ecs_anim.io.export.onto.recorded_on_rig`) and written in its
hierarchy.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.checks import found
from ecs_anim.core.errors import UsageError, listed, quoted
from ecs_anim.core.files import output_set
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINTS, N_LENGTHS
from ecs_anim.io.export import (
    EXPORT_NAMES,
    Rig,
    bvh_from_rotations,
    glb_bytes,
    onto_rig_bytes,
    recorded_on_rig,
    rig_of,
    write_npz,
)
from ecs_anim.runtime.triggers import Event

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: The files :meth:`Recorder.save` can write per character, in the order it writes them.
EXPORT_FORMATS = ("bvh", "npz", "glb")
_FILE_NAME = re.compile(r"^(?!\.\.?$)[^/\\\x00]+$")


@dataclass(frozen=True)
class RecordedCharacter:
    """What a :class:`Recorder` holds of one character, from its first recorded tick to its
    removal (or the last tick recorded).

    Attributes
    ----------
    entity, name : the character (its name when it was first seen).
    body : its rest body for export: the body it was last given (``sim.body``), on the segment
        lengths of its last recorded posture (they differ only while a blend was still going).
    start_s : simulation time of its first recorded posture (s).
    removed_at_s : time of the first recorded posture without it (s), None if never removed.
    positions : (frames, 22, 3) world joint positions, metres, Z up (``ecs_anim.JOINTS``).
    local_rotations : (frames, 25, 3, 3) the export skeleton's local rotations, BVH axes.
    lengths : (frames, N_LENGTHS) segment lengths each posture was made on, metres.
    contacts : (frames, 2) bool, left and right foot fully planted.
    """

    entity: int
    name: str
    body: Morphology
    start_s: float
    removed_at_s: float | None
    positions: F64
    local_rotations: F64
    lengths: F64
    contacts: NDArray[np.bool_]

    @property
    def frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def body_changed(self) -> bool:
        """Whether some recorded posture was made on other lengths than :attr:`body`'s."""
        return bool(np.any(self.lengths != self.body.lengths))


class Recorder:
    """Collects every tick of a simulation for export; made by ``Simulation.record``.

    ``entities``: the characters to record (None: every character, those spawned later too).
    """

    def __init__(self, sim: Simulation, entities: Iterable[int] | None = None):
        self.sim = sim
        self.follow_all = entities is None
        #: Every recorded tick's posture time (s) and the events of those ticks, in order.
        self.times_s: list[float] = []
        self.events: list[Event] = []
        # Per character (k,), in the order first seen: entity, name, body, first and last
        # recorded tick (indices into times_s; -1: none yet).
        self.entities = np.zeros(0, np.int64)
        self.names: list[str] = []
        self.bodies: list[Morphology] = []
        self.first_tick = np.zeros(0, np.int64)
        self.last_tick = np.zeros(0, np.int64)
        self._index_of = np.zeros(0, np.int64)  # entity -> index here (-1: not recorded)
        self._bodies_version = -1
        # Stretches of ticks recording the same characters in the same rows: (their indices
        # here (r,), per tick positions, local rotations, lengths, contacts).
        self._stretches: list[tuple[I64, list[list[NDArray[Any]]]]] = []
        self._stacked: list[tuple[I64, list[NDArray[Any]]]] | None = None
        self.collecting = True
        if entities is not None:
            if isinstance(entities, (str, bytes)) or not isinstance(entities, Iterable):
                raise UsageError(f"record: entities must be a list of entities, got "
                                 f"{found(entities)}")
            wanted = list(entities)
            for entity in wanted:
                if isinstance(entity, bool) or not isinstance(entity, (int, np.integer)):
                    raise UsageError(f"record: entities must be entities (int), got "
                                     f"{found(entity)}")
                sim.row(int(entity))  # an unknown entity is refused here
            ids = np.unique(np.array(wanted, np.int64))
            self._add(ids, [sim.row(int(e)) for e in ids])

    # --- collecting -------------------------------------------------------------------------

    def collect(self) -> None:
        """Take the posture just stepped (``Simulation.step`` calls it after each tick)."""
        if not self.collecting:
            return
        sim, st = self.sim, self.sim.store
        self._grow_index(st.entity)
        at = self._index_of[st.entity]  # (n,) each row's index here, -1: not recorded
        if self.follow_all and np.any(at < 0):
            new = np.flatnonzero(at < 0)
            self._add(st.entity[new], new.tolist())
            at = self._index_of[st.entity]
        if sim.structure_version != self._bodies_version:
            self._refresh_bodies()
        rows = np.flatnonzero(at >= 0)
        which = at[rows]
        tick = len(self.times_s)
        self.times_s.append(sim.posture_time_s)
        self.events += sim.events()
        if not self._stretches or not np.array_equal(self._stretches[-1][0], which):
            self._stretches.append((which, [[], [], [], []]))
        positions, rotations, lengths, contacts = self._stretches[-1][1]
        every = rows.shape[0] == st.n  # the whole arrays (copies), not a gather
        pick: slice | I64 = slice(None) if every else rows
        positions.append(st.positions[pick].copy())
        rotations.append(st.local_rotations[pick].copy())
        lengths.append(st.lengths[pick].copy())
        contacts.append(st.contact_weight[pick] >= 1.0)
        self.first_tick[which[self.first_tick[which] < 0]] = tick
        self.last_tick[which] = tick
        self._stacked = None  # read again with this tick

    def stop(self) -> None:
        """Stop collecting (what was recorded stays; :meth:`save` still writes it)."""
        self.collecting = False
        if self in self.sim.recorders:
            self.sim.recorders.remove(self)

    def _grow_index(self, ids: I64) -> None:
        size = int(ids.max(initial=-1)) + 1
        if size > self._index_of.shape[0]:
            self._index_of = np.concatenate(
                [self._index_of, np.full(size - self._index_of.shape[0], -1, np.int64)])

    def _add(self, entities: I64, rows: list[int]) -> None:
        """Characters seen for the first time (their store ``rows``): names and bodies read."""
        self._grow_index(entities)
        self._index_of[entities] = self.entities.shape[0] + np.arange(entities.shape[0])
        names = self.sim.names()
        self.entities = np.concatenate([self.entities, entities])
        self.names += [names[r] for r in rows]
        self.bodies += [self.sim.body(int(e)) for e in entities]
        self.first_tick = np.concatenate([self.first_tick, np.full(entities.shape[0], -1)])
        self.last_tick = np.concatenate([self.last_tick, np.full(entities.shape[0], -1)])

    def _refresh_bodies(self) -> None:
        """After a structural change: each recorded character's Morphology component (a
        replaced body shows here; a removed character keeps the one it had)."""
        rows, bodies = self.sim.rows_and_components(Morphology)
        at = self._index_of[self.sim.store.entity[rows]] if rows.size else rows
        for index, body in zip(at.tolist(), bodies, strict=True):
            if index >= 0:
                self.bodies[index] = body
        self._bodies_version = self.sim.structure_version

    # --- reading ----------------------------------------------------------------------------

    def characters(self) -> list[RecordedCharacter]:
        """Every recorded character, in the order first seen (a character removed before its
        first recorded posture has no frames)."""
        return [self._character(i) for i in range(self.entities.shape[0])]

    def character(self, entity: int) -> RecordedCharacter:
        """One character's recording, by its entity (valid after its removal too)."""
        if isinstance(entity, bool) or not isinstance(entity, (int, np.integer)):
            raise UsageError(f"character: expected an entity (int), got {found(entity)}")
        known = 0 <= entity < self._index_of.shape[0] and self._index_of[entity] >= 0
        if not known:
            raise UsageError(f"character: entity {entity!r} is not recorded by this recorder")
        return self._character(int(self._index_of[entity]))

    def _character(self, i: int) -> RecordedCharacter:
        if self._stacked is None:  # each stretch's ticks as arrays (frames, r, ...), once
            self._stacked = [(which, [np.stack(values) for values in ticks])
                             for which, ticks in self._stretches]
        columns: list[list[NDArray[Any]]] = [[], [], [], []]
        for which, stacked in self._stacked:
            column = np.flatnonzero(which == i)
            if column.size:
                for out, values in zip(columns, stacked, strict=True):
                    out.append(values[:, column[0]])
        positions, rotations, lengths, contacts = (
            np.concatenate(c) if c else np.zeros((0, *shape), dtype) for c, shape, dtype in
            zip(columns, ((len(JOINTS), 3), (len(EXPORT_NAMES), 3, 3), (N_LENGTHS,), (2,)),
                (float, float, float, bool), strict=True))
        body = self.bodies[i]
        if lengths.shape[0] and np.any(lengths[-1] != body.lengths):  # a blend not over
            body = Morphology(lengths[-1].copy(), body.mass_kg, body.sex, body.name)
        first, last = int(self.first_tick[i]), int(self.last_tick[i])
        removed = None
        if first >= 0 and last + 1 < len(self.times_s):
            removed = self.times_s[last + 1]
        return RecordedCharacter(
            int(self.entities[i]), self.names[i], body,
            self.times_s[first] if first >= 0 else float("nan"), removed,
            positions, rotations, lengths, contacts)

    # --- writing ----------------------------------------------------------------------------

    def save(self, folder: str | Path, formats: Sequence[str] = EXPORT_FORMATS,
             onto: str | Path | Rig | None = None, force: bool = False,
             rig_map: str | None = None) -> list[Path]:
        """Write ``<character>.bvh``, ``.npz`` and ``.glb`` (those of ``formats``) for every
        recorded character with at least one posture into ``folder``, as one set: the files go
        into a hidden sibling folder and replace ``folder`` in one atomic rename
        (:func:`ecs_anim.core.files.output_set`, as ``ecs-anim run --export`` does), so
        ``folder`` holds the old set or the new one, never a mix. An existing ``folder`` is
        replaced only with ``force``, and only if it holds nothing but export files.

        ``onto``: a user's rig (a .bvh, .glb, .gltf or .fbx file, or a loaded
        :class:`~ecs_anim.io.export.rig.Rig`; its joint map ``rig_map``, a preset or a map YAML,
        as import's ``--map``): every character is retargeted onto the rig's body
        (:func:`~ecs_anim.io.export.onto.recorded_on_rig`) and its ``.bvh`` and ``.glb`` written
        in the rig's hierarchy, its ``.npz`` our joints on that body, as ``export --onto``
        writes a clip. Returns the files written, in order."""
        if onto is not None and not isinstance(onto, (str, Path, Rig)):
            raise UsageError(f"save: onto must be a rig file's path or a Rig, got {found(onto)}")
        if isinstance(formats, str) or not isinstance(formats, Sequence):
            raise UsageError(f"save: formats must be a list of {listed(EXPORT_FORMATS)}, got "
                             f"{found(formats)}")
        unknown = [f for f in formats if f not in EXPORT_FORMATS]
        if unknown or not formats:
            raise UsageError(f"save: formats must be some of {listed(EXPORT_FORMATS)}, got "
                             f"{found(list(formats))}")
        kinds = [f for f in EXPORT_FORMATS if f in formats]
        rig = None if onto is None else rig_of(onto, rig_map)
        characters = [c for c in self.characters() if c.frames]
        bad = [c.name for c in characters if not _FILE_NAME.match(c.name)]
        if bad:
            raise UsageError(f"save: character names {listed([quoted(n) for n in bad])} cannot "
                             "be file names")
        twice = [name for name, count in Counter(c.name for c in characters).items() if count > 1]
        if twice:
            raise UsageError(f"save: several recorded characters are named "
                             f"{listed([quoted(n) for n in twice])}; their files would collide "
                             "(give characters unique names)")
        names = [f"{c.name}.{kind}" for c in characters for kind in kinds]
        fps = self.sim.fps
        with output_set(folder, names, force) as export:
            for c in characters:
                if rig is not None:
                    pose = recorded_on_rig(rig, c.positions, c.local_rotations, c.lengths)
                    for kind in kinds:
                        with export.file(f"{c.name}.{kind}") as f:
                            f.write(onto_rig_bytes(rig, pose, kind, fps, c.contacts))
                    continue
                # (A body that never changed gives the same bytes as without lengths.)
                for kind in kinds:
                    with export.file(f"{c.name}.{kind}") as f:
                        if kind == "bvh":
                            f.write(bvh_from_rotations(c.body, c.positions[:, 0],
                                                       c.local_rotations, fps,
                                                       c.lengths).encode("utf-8"))
                        elif kind == "npz":
                            write_npz(f, c.positions, fps, c.contacts)
                        else:
                            f.write(glb_bytes(c.body, c.positions[:, 0], c.local_rotations,
                                              fps, c.lengths))
        return [Path(folder) / name for name in names]
