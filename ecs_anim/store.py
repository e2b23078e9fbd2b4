"""The structure-of-arrays store every system works on: one row per character.

Gathering and scattering go through here only (STYLE 12): rows are added when characters spawn
(load time, not in the tick), specification changes write one row, and each system reads and
writes whole arrays. Field writers are declared in each system's docstring.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from .normalized import TRAILING_SHAPES, DecodedPose, NormalizedPoses
from .morphology import MASS_SEGMENTS
from .skeleton import N_JOINTS, N_LENGTHS

F64 = NDArray[np.float64]

N_MASS_SEGMENTS = len(MASS_SEGMENTS)

#: Most clips a character can have queued at once.
MAX_QUEUE = 16
#: Fields that are not one array row per character: the poses (arrays of their own) and what the
#: tick derives from them.
NOT_ROWS = ("poses", "scaled", "vertebrae", "goals", "solved_positions", "posture")


def _empty_poses(n: int) -> NormalizedPoses:
    arrays = {}
    for name, trailing in TRAILING_SHAPES.items():
        a = np.zeros((n,) + trailing)
        if trailing and trailing[-1] == 4:
            a[..., 3] = 1.0
        arrays[name] = a
    return NormalizedPoses(**arrays)


@dataclass
class CharacterStore:
    """Per-character arrays; ``n`` rows. Units: metres, seconds, radians; world Z up.

    entity (n,) esper entity ids; lengths (n, N_LENGTHS) segment lengths;
    clip (n,) clip index in the bank; clip_time_s (n,); speed (n,); loop (n,) bool;
    fade_clip, fade_time_s, fade_loop (n,) the clip being faded out, fade_s (n,) its crossfade
    duration (0: none), fade_elapsed_s (n,); queue: per row, clips still to play;
    placement_xy (n, 2) metres and placement_heading (n,) of each motion origin (fade_placement_*
    the same for the clip being faded out);
    poses: this tick's normalized poses (n,); contact_weight (n, 2) foot-contact activation;
    scaled: the pose decoded on each body before ground adaptation;
    footprint (n, 2, 3) locked ankle positions, locked (n, 2) bool, footprint_settled (n, 2) bool
    (the contact has been fully planted: its footprint's height is fixed); ground_ref (n,) metres the
    motion's floor is raised to under the character (smoothed);
    positions (n, N_JOINTS, 3) and local_rotations (n, n_export, 3, 3): the output posture;
    vertebrae (n, k, 3) a finer spine when the simulation asks for one;
    frozen (n,) bool: characters whose pose went bad, held at their last good posture;
    segment_mass_kg, segment_com_fraction (n, segments): each body's de Leva segment masses and
    centre-of-mass positions; com_control (n,) bool; com_target_xy (n, 2) a desired horizontal
    centre of mass given by the scenario (NaN: the motion's own); com_desired (n, 3) where the
    centre of mass should be this tick; com (n, 3) where it is after the solve and com_error_m
    (n,) its horizontal distance from com_desired (NaN for characters nothing constrained);
    posture: the last tick's decoded posture (frames too), which targets on other characters read.
    """

    entity: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    lengths: F64 = field(default_factory=lambda: np.zeros((0, N_LENGTHS)))
    clip: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    clip_time_s: F64 = field(default_factory=lambda: np.zeros(0))
    speed: F64 = field(default_factory=lambda: np.zeros(0))
    loop: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    fade_clip: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    fade_time_s: F64 = field(default_factory=lambda: np.zeros(0))
    fade_loop: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    fade_s: F64 = field(default_factory=lambda: np.zeros(0))
    fade_elapsed_s: F64 = field(default_factory=lambda: np.zeros(0))
    placement_xy: F64 = field(default_factory=lambda: np.zeros((0, 2)))
    placement_heading: F64 = field(default_factory=lambda: np.zeros(0))
    fade_placement_xy: F64 = field(default_factory=lambda: np.zeros((0, 2)))
    fade_placement_heading: F64 = field(default_factory=lambda: np.zeros(0))
    contact_weight: F64 = field(default_factory=lambda: np.zeros((0, 2)))
    footprint: F64 = field(default_factory=lambda: np.zeros((0, 2, 3)))
    locked: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, 2), bool))
    footprint_settled: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, 2), bool))
    ground_ref: F64 = field(default_factory=lambda: np.zeros(0))
    positions: F64 = field(default_factory=lambda: np.zeros((0, N_JOINTS, 3)))
    local_rotations: F64 = field(default_factory=lambda: np.zeros((0, 0, 3, 3)))
    frozen: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    segment_mass_kg: F64 = field(default_factory=lambda: np.zeros((0, N_MASS_SEGMENTS)))
    segment_com_fraction: F64 = field(default_factory=lambda: np.zeros((0, N_MASS_SEGMENTS)))
    com_control: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    com_target_xy: F64 = field(default_factory=lambda: np.zeros((0, 2)))
    com_desired: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    com: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    com_error_m: F64 = field(default_factory=lambda: np.zeros(0))
    queue_clip: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, MAX_QUEUE), np.int64))
    queue_fade_s: F64 = field(default_factory=lambda: np.zeros((0, MAX_QUEUE)))
    queue_loop: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, MAX_QUEUE), bool))
    queue_head: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    queue_len: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    poses: NormalizedPoses = field(default_factory=lambda: _empty_poses(0))
    scaled: DecodedPose | None = None
    vertebrae: F64 | None = None
    goals: object | None = None  # this tick's constraint goals (ecs_anim.solver_shell.TickGoals)
    solved_positions: F64 | None = None  # (r, N_JOINTS, 3) the solver's result for goals.rows
    posture: DecodedPose | None = None

    @property
    def n(self) -> int:
        return int(self.entity.shape[0])

    def add_row(self, **values: object) -> int:
        """Append one character; ``values`` give its row for any array field. Load time only."""
        row = self.n
        for f in fields(self):
            if f.name in NOT_ROWS:
                continue
            current = getattr(self, f.name)
            fill = np.zeros((1,) + current.shape[1:], dtype=current.dtype)
            if f.name in values:
                fill[0] = values[f.name]
            setattr(self, f.name, np.concatenate([current, fill]))
        one = _empty_poses(1)
        self.poses = NormalizedPoses(**{k: np.concatenate([v, getattr(one, k)])
                                        for k, v in self.poses.arrays().items()})
        self.scaled = None
        self.vertebrae = None
        if self.posture is not None:  # no last tick for the new row: NaN, read as "none"
            self.posture = DecodedPose(**{
                f.name: np.concatenate([getattr(self.posture, f.name),
                                        np.full((1,) + getattr(self.posture, f.name).shape[1:], np.nan)])
                for f in fields(DecodedPose)})
        return row

    def remove_row(self, row: int) -> None:
        """Delete one character's row; the rows after it move down by one. Not in the tick.

        This tick's derived arrays (goals, the solver's result, vertebrae) are dropped: the next
        tick makes them again."""
        keep = np.arange(self.n) != row
        for f in fields(self):
            if f.name not in NOT_ROWS:
                setattr(self, f.name, getattr(self, f.name)[keep])
        self.poses = self.poses.take(keep)
        self.scaled = None if self.scaled is None else self.scaled.take(keep)
        self.posture = None if self.posture is None else self.posture.take(keep)
        self.vertebrae = self.goals = self.solved_positions = None
