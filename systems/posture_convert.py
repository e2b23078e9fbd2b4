"""PostureConvert: rebuild knees, elbows and vertebrae and give the world posture (paper §8).

Rows: every character; under a frame budget that cannot hold otherwise, those due this tick
(:mod:`ecs_anim.runtime.update_rate`: the others keep their posture).
Reads: store.poses, store.lengths, frozen, and the last good positions, local_rotations and
vertebrae (kept for a frozen character); store.goals and solved: the characters the solver moved
are not decoded again, their pose as the solver decoded it is taken
(:func:`ecs_anim.runtime.kernels.solved_posture.posture_solved_rows`).
Writes: store.positions (world joint positions), store.posture (the same with the body frames,
for next tick's targets on other characters), store.local_rotations (the BVH export skeleton's
local joint rotation matrices, when the simulation asks for rotations), store.vertebrae (when
it asks for a finer spine), store.frozen (a character whose pose went non-finite keeps its last
good posture and is reported once). All in place (but store.posture's frames, which are the
solver's arrays when it solved every character), by the compiled
:func:`ecs_anim.runtime.kernels.posture.posture_rows`, or while the kernels compile aside by its
numpy reference (:func:`posture_numpy`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import decode, vertebrae
from ecs_anim.core.skeleton import N_JOINTS
from ecs_anim.io.export.skeleton import local_rotations
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import (
    DecodedArrays,
    decoded_arrays,
    decoded_pose,
    empty_decoded,
    fits,
    pose_arrays,
    spine_scratch,
    spine_scratch_fits,
)
from ecs_anim.runtime.kernels.posture import N_EXPORT, export_constants, posture_rows
from ecs_anim.runtime.kernels.solved_posture import posture_solved_rows
from ecs_anim.runtime.system_base import System

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

_EXPORT = export_constants()


def posture_numpy(sim: Simulation, rows: NDArray[np.int64], decoded: DecodedArrays,
                  newly_bad: NDArray[np.bool_], have_previous: bool,
                  solved: DecodedArrays | None = None) -> None:
    """The numpy reference of :func:`~ecs_anim.runtime.kernels.posture.posture_rows` (with
    ``solved``, (r, ...) the solver's decoded rows: of
    :func:`~ecs_anim.runtime.kernels.solved_posture.posture_solved_rows`) over the store rows
    ``rows`` (r,), all at once, in place: ``decoded`` (n, ...) gets their decoded pose; the
    store's frozen, positions, local_rotations (with ``sim.rotations``) and vertebrae (with
    ``sim.vertebrae``; a frozen row's only without ``have_previous``); ``newly_bad`` (n,) the
    rows frozen now that were not."""
    st = sim.store
    poses, lengths = st.poses.take(rows), st.lengths[rows]
    fresh = decoded_arrays(decode(poses, lengths)) if solved is None else solved
    for target, value in zip(decoded, fresh, strict=True):
        target[rows] = value
    good = np.isfinite(fresh.positions).all(axis=(1, 2))
    rotations = bool(sim.rotations) and st.local_rotations.shape == (st.n, N_EXPORT, 3, 3)
    if rotations:
        local = local_rotations(decoded_pose(fresh))
        good &= np.isfinite(local).all(axis=(1, 2, 3))
    newly_bad[rows] = ~good & ~st.frozen[rows]
    st.frozen[rows] = ~good
    st.positions[rows[good]] = fresh.positions[good]
    if rotations:
        st.local_rotations[rows[good]] = local[good]
    count = int(sim.vertebrae)
    if count and st.vertebrae is not None:
        write = np.flatnonzero(good | (not have_previous))
        if write.size:
            st.vertebrae[rows[write]] = vertebrae(poses.take(write), lengths[write], count)


def _writable(a: np.ndarray, shape: tuple[int, ...]) -> bool:
    """Whether the kernels can write ``a`` as it is: its ``shape``, float64, writable and
    C-contiguous (the decode's results are put back through flat views)."""
    return (a.shape == shape and a.dtype == np.float64 and a.flags.writeable
            and a.flags.c_contiguous)


class PostureConvert(System):
    follows_update_rate = True
    reads = ("poses", "lengths", "frozen", "positions", "local_rotations", "vertebrae", "goals",
             "solved")
    writes = ("frozen", "positions", "posture", "local_rotations", "vertebrae")

    def __init__(self, sim: Simulation) -> None:
        super().__init__(sim)
        # The kernels' scratch, kept from tick to tick (allocated and first touched again every
        # tick otherwise): positions (n, N_JOINTS, 3), of which each thread's chunk uses its
        # first BLOCK rows with rotations (a block's positions before its decode; the pages
        # after them are never touched), the spines' block scratches (spine_scratch).
        self._positions = np.empty((0, N_JOINTS, 3))
        self._spines = spine_scratch(0)

    def _scratch(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The positions' scratch for ``n`` store rows and the spine scratch for as many rows
        decoded (:func:`~ecs_anim.runtime.kernels.decode.spine_scratch`)."""
        if self._positions.shape[0] != n:
            self._positions = np.empty((n, N_JOINTS, 3))
        if not spine_scratch_fits(self._spines, n):
            self._spines = spine_scratch(n)
        return self._positions, self._spines

    def run(self, dt: float) -> None:
        st, sim = self.sim.store, self.sim
        n = st.n
        if not _writable(st.positions, (n, N_JOINTS, 3)):
            st.positions = np.array(st.positions, dtype=np.float64)
        solved, solved_rows = None, np.zeros(0, np.int64)
        if st.goals is not None and st.solved is not None:  # decoded once, by the solver
            solved = decoded_arrays(st.solved)
            solved_rows = np.asarray(st.goals.rows, dtype=np.int64)  # type: ignore[attr-defined]
        # Every row solved (the rows sorted and distinct: all of them, in order): the posture's
        # frames are the solver's arrays themselves, not copied (2 MB at 4,000 characters; the
        # solver makes new ones every tick, and nothing else keeps these).
        frames_shared = solved is not None and solved_rows.size == n and fits(solved, n)
        if solved is not None and frames_shared:
            frames = solved
        elif fits(st.posture, n):
            frames = decoded_arrays(st.posture)  # type: ignore[arg-type]
        else:
            frames = empty_decoded(n)
        positions, spines = self._scratch(n)
        # The kernels write the store's positions; the positions in ``decoded`` are scratch.
        decoded = frames._replace(positions=positions)
        # Joint rotations cost more than the positions; they are made when something uses them
        # (BVH export, a viewer drawing skinned meshes): ``Simulation(rotations=True)``.
        rotations = bool(sim.rotations)
        # (arrays made anew this tick are filled for every row: those resting too)
        made_anew = rotations and not _writable(st.local_rotations, (n, N_EXPORT, 3, 3))
        if made_anew:
            st.local_rotations = np.broadcast_to(np.eye(3), (n, N_EXPORT, 3, 3)).copy()
        count = int(sim.vertebrae)
        have_previous = (count > 0 and st.vertebrae is not None
                         and _writable(st.vertebrae, (n, count, 3)))
        if count and not have_previous:
            st.vertebrae = np.empty((n, count, 3))
            made_anew = True
        spine = st.vertebrae if count and st.vertebrae is not None else np.empty((n, 0, 3))
        k = _EXPORT
        newly_bad = np.zeros(n, bool)
        pose = pose_arrays(st.poses)
        rest = (st.frozen, newly_bad, st.positions, rotations,
                np.empty((n if rotations else 0, N_EXPORT, 3, 3)),
                st.local_rotations if rotations else np.empty((0, N_EXPORT, 3, 3)),
                k.rest_hips, k.bvh_from_world, k.rest2body, k.parents, spine, have_previous)
        # (all but those resting; writable, the kernels' one compiled specialisation)
        decode_rows = (self.rows() if made_anew
                       else sim.update_rate.due_rows(sim, self.rows())).copy()
        if solved is not None:
            decode_rows = np.delete(decode_rows, solved_rows) if decode_rows.size == n \
                else np.setdiff1d(decode_rows, solved_rows, assume_unique=True)
            if sim.compiled:
                over_chunks(posture_solved_rows, solved_rows.size, solved_rows, solved, pose,
                            st.lengths, decoded, *rest, frames_shared)
            else:
                posture_numpy(sim, solved_rows, decoded, newly_bad, have_previous, solved)
        if sim.compiled:
            over_chunks(posture_rows, decode_rows.size, decode_rows, pose, st.lengths, decoded,
                        *rest, spines)
        else:  # the kernels compile aside (a first run)
            posture_numpy(sim, decode_rows, decoded, newly_bad, have_previous)
        if newly_bad.any():
            sim.report_frozen(np.flatnonzero(newly_bad))
        # Next tick's targets on other characters read this posture, frames included.
        st.posture = decoded_pose(decoded._replace(positions=st.positions))
