"""The structure-of-arrays store every system works on: one row per character.

Gathering and scattering go through here only (STYLE 12): rows are added when characters spawn
(load time, not in the tick), specification changes write one row, and each system reads and
writes whole arrays. Each system declares the fields it reads and writes (``System.reads`` /
``writes``, checked by tests/ecs/test_ecs.py); :data:`SPEC_FIELDS` are written outside the tick
(spawn, ``Simulation.set_*``) and read by the systems as their inputs.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError
from ecs_anim.core.morphology import MASS_SEGMENTS
from ecs_anim.core.normalized import TRAILING_SHAPES, DecodedPose, NormalizedPoses
from ecs_anim.core.skeleton import N_JOINTS, N_LENGTHS
from ecs_anim.solver.capsules import N_CAPSULES
from ecs_anim.solver.joint_speed import N_VALUES

F64 = NDArray[np.float64]

N_MASS_SEGMENTS = len(MASS_SEGMENTS)

#: Most clips a character can have queued at once.
MAX_QUEUE = 16
#: Most waypoints a steered character's path holds (its start point included).
MAX_WAYPOINTS = 128
#: Fields that are not one array row per character: the poses (arrays of their own) and what the
#: tick derives from them.
NOT_ROWS = ("poses", "vertebrae", "goals", "solved", "posture", "columns", "clip_positions")
#: Fields set when a character spawns or a specification component is replaced, between ticks:
#: the systems' inputs (a system may also write one, e.g. MorphologyAdapt takes a new body in).
SPEC_FIELDS = ("entity", "lengths", "speed", "queue_clip", "queue_fade_s", "queue_loop",
               "queue_len", "segment_mass_kg", "segment_com_fraction", "com_control",
               "com_target_xy", "ground_index", "constraints", "path_xy", "path_len",
               "path_cum_m", "gait_clip")


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
    sole_roll (n, 2) the part of each foot the motion plants (0 heel, 1 ball, 0.5 both:
    :data:`ecs_anim.core.ground_adapt.HEEL_ROLL`); footprint (n, 2, 3) the sole point each foot in
    contact stands on (world metres, on the ground), pivot (n, 2) which (0 heel, 1 ball), locked
    (n, 2) bool (a footprint is laid); ground_ref (n,) metres the
    motion's floor is raised to under the character (smoothed);
    positions (n, N_JOINTS, 3) and local_rotations (n, n_export, 3, 3): the output posture;
    vertebrae (n, k, 3) a finer spine when the simulation asks for one;
    frozen (n,) bool: characters whose pose went bad, held at their last good posture;
    segment_mass_kg, segment_com_fraction (n, segments): each body's de Leva segment masses and
    centre-of-mass positions; com_control (n,) bool; com_target_xy (n, 2) a desired horizontal
    centre of mass given by the scenario (NaN: the motion's own); com_desired (n, 3) where the
    centre of mass should be this tick; com (n, 3) where it is after the solve and com_error_m
    (n,) its horizontal distance from com_desired (NaN for characters nothing constrained);
    posture: the last tick's decoded posture (frames too), which targets on other characters read;
    ground_index (n,) the ground each character stands on: 0 the environment's, k > 0
    ``Simulation.grounds[k]`` (a GroundQuery of the character's own).
    Steering (:mod:`ecs_anim.runtime.steering`): steer_mode (n,) 0 none, 1 heading and speed, 2 a path;
    steer_heading_rad (n,) the heading wanted; steer_speed_m_s (n,) the speed wanted (NaN: the
    walk's own); path_xy (n, MAX_WAYPOINTS, 2) metres, the path's points (its first: where the
    character was when given it), path_len (n,) how many, path_cum_m (n, MAX_WAYPOINTS) the arc
    length at each (m; beyond the last: its total), path_progress_m (n,) arc length done;
    gait_clip (n, 3) the clips of the locomotion set [idle, walk, run] (-1: none), gait (n,) the
    one playing (index into those columns); fade_keeps_contacts (n,) bool: the running
    cross-fade keeps a foot down in both clips on its footprint; fade_speed (n,) the playback
    rate of the clip being faded out (its rate when the fade began).
    Collisions (:mod:`ecs_anim.solver.capsules`, CollisionSeparate): capsule_ends
    (n, N_CAPSULES, 2, 3) world metres, each capsule's axis (shank l/r, thigh l/r, pelvis, trunk,
    head, upper arm l/r, forearm l/r, hand l/r) and capsule_radii (n, N_CAPSULES) m, as the
    tick ends, for the characters whose bounds meet another's (the others' rows NaN);
    overlap_m (n,) each character's deepest overlap with another after separation (m).
    No pops (:mod:`ecs_anim.solver.joint_speed`, ConstraintSolve): last_clip_values and
    last_pose_values (n, N_VALUES) the segments the solver sets (frames, directions, fractions,
    spine points, packed) of the last tick's motion pose (zeros: none) and of its result, which
    this tick's result may move away from only so much faster than the motion;
    last_clip_positions and last_pose_positions (n, N_JOINTS, 3) world m, the last tick's
    motion's and result's joints (the bound measures them from the pelvis); the result's kept
    only in the rows last_kept (n,) bool (solved, held or going back then: every other row was
    at its motion's pose);
    clip_positions (n, N_JOINTS, 3) world m, the motion's own joints this tick, before the solve
    (None when nothing was solved nor goes back: the posture is the motion's own; NaN in the rows
    not decoded: with a frame budget those neither solved nor going back this tick, with nothing
    solved those not going back).
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
    pivot: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    sole_roll: F64 = field(default_factory=lambda: np.full((0, 2), 0.5))
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
    ground_index: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    steer_mode: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    steer_heading_rad: F64 = field(default_factory=lambda: np.zeros(0))
    steer_speed_m_s: F64 = field(default_factory=lambda: np.zeros(0))
    path_xy: F64 = field(default_factory=lambda: np.zeros((0, MAX_WAYPOINTS, 2)))
    path_len: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    path_cum_m: F64 = field(default_factory=lambda: np.zeros((0, MAX_WAYPOINTS)))
    path_progress_m: F64 = field(default_factory=lambda: np.zeros(0))
    gait_clip: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    gait: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    fade_keeps_contacts: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    fade_speed: F64 = field(default_factory=lambda: np.zeros(0))
    capsule_ends: F64 = field(default_factory=lambda: np.zeros((0, N_CAPSULES, 2, 3)))
    capsule_radii: F64 = field(default_factory=lambda: np.zeros((0, N_CAPSULES)))
    overlap_m: F64 = field(default_factory=lambda: np.zeros(0))
    last_clip_values: F64 = field(default_factory=lambda: np.zeros((0, N_VALUES)))
    last_pose_values: F64 = field(default_factory=lambda: np.zeros((0, N_VALUES)))
    last_pose_positions: F64 = field(default_factory=lambda: np.zeros((0, N_JOINTS, 3)))
    last_clip_positions: F64 = field(default_factory=lambda: np.zeros((0, N_JOINTS, 3)))
    last_kept: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    queue_clip: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, MAX_QUEUE), np.int64))
    queue_fade_s: F64 = field(default_factory=lambda: np.zeros((0, MAX_QUEUE)))
    queue_loop: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, MAX_QUEUE), bool))
    queue_head: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    queue_len: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    poses: NormalizedPoses = field(default_factory=lambda: _empty_poses(0))
    vertebrae: F64 | None = None
    goals: object | None = None  # this tick's constraint goals (ecs_anim.solver.goals.TickGoals)
    solved: DecodedPose | None = None  # (r, ...) the solver's decoded result for goals.rows
    posture: DecodedPose | None = None
    clip_positions: F64 | None = None
    #: Columns of the user's own systems (:meth:`add_column`): name -> (n, ...) array, one row
    #: per character like every field above, grown and shrunk with the characters.
    columns: dict[str, np.ndarray] = field(default_factory=dict)

    #: Growth buffers behind each array: field name (``"poses.root_position"`` for a pose
    #: array) -> (the buffer, the view of its first ``n`` rows handed out as the attribute).
    _buffers: dict[str, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, init=False, repr=False, compare=False)
    #: Each user column's value for new rows.
    _column_fill: dict[str, object] = field(default_factory=dict, init=False, repr=False,
                                            compare=False)

    @property
    def n(self) -> int:
        return int(self.entity.shape[0])

    def add_column(self, name: str, trailing_shape: tuple[int, ...] = (), dtype: type = np.float64,
                   fill: object = 0) -> np.ndarray:
        """A per-character column of the user's own: ``columns[name]``, shape
        ``(n,) + trailing_shape``, every row (today's characters and those spawned later) set to
        ``fill`` until a system writes it; a removed character's row goes with it. Returns it.
        Raises ValueError when a column of that name exists or the name is a store field."""
        if not name.isidentifier():
            raise UsageError(f"column {name!r}: a column's name is a Python identifier")
        if name in self.columns or name in _ROW_FIELDS or name in NOT_ROWS:
            raise UsageError(f"column {name!r}: the store has a column or field of that name already")
        self._column_fill[name] = fill
        self.columns[name] = np.full((self.n,) + tuple(trailing_shape), fill, dtype)
        return self.columns[name]

    def add_row(self, **values: object) -> int:
        """Append one character; ``values`` give its row for any array field. Load time only."""
        return int(self.add_rows(1, **{k: np.asarray(v)[None] for k, v in values.items()})[0])

    def add_rows(self, count: int, **values: object) -> NDArray[np.int64]:
        """Append ``count`` characters at once; ``values`` give, for any array field, their
        rows ``(count, ...)`` (or one row broadcast to all); other fields start at zero (poses
        at the identity, the last posture at NaN: "none yet"). Returns the new rows. Load time.

        The arrays grow by capacity doubling: each field is a view of the first ``n`` rows of a
        larger buffer, so spawning ``k`` characters one by one costs O(k), not O(k^2). A system
        may still replace a whole field (``st.contact_weight = weights``): the new array becomes
        that field's buffer, and the next spawn copies it into a grown one."""
        n = self.n
        for name in _ROW_FIELDS:
            fill = values.get(name)
            self._grow(self, name, name, count, 0 if fill is None else fill)
        for name, trailing in TRAILING_SHAPES.items():
            identity = 1.0 if trailing and trailing[-1] == 4 else None
            self._grow(self.poses, name, f"poses.{name}", count, 0.0, identity)
        for name, fill in self._column_fill.items():
            self.columns[name] = self._grown(self.columns[name], f"columns.{name}", count, fill)
        self.vertebrae = self.clip_positions = None
        if self.posture is not None:  # no last tick for the new rows: NaN, read as "none"
            for f in fields(DecodedPose):
                self._grow(self.posture, f.name, f"posture.{f.name}", count, np.nan)
        return np.arange(n, n + count, dtype=np.int64)

    def _grow(self, holder: object, name: str, key: str, count: int, fill: object,
              quaternion_w: float | None = None) -> None:
        """Append ``count`` rows set to ``fill`` to ``holder.name`` (buffer ``key``)."""
        view = self._grown(getattr(holder, name), key, count, fill, quaternion_w)
        setattr(holder, name, view)

    def _grown(self, current: np.ndarray, key: str, count: int, fill: object,
               quaternion_w: float | None = None) -> np.ndarray:
        """``current`` with ``count`` rows set to ``fill`` appended, in buffer ``key``."""
        n = current.shape[0]
        buffer, view = self._buffers.get(key, (None, None))
        if buffer is None or view is not current:  # replaced since: adopt the new array
            buffer = current
        if buffer.shape[0] < n + count or buffer.shape[1:] != current.shape[1:]:
            grown = np.empty((max(2 * (n + count), 16),) + current.shape[1:], current.dtype)
            grown[:n] = current
            buffer = grown
        buffer[n:n + count] = fill
        if quaternion_w is not None:
            buffer[n:n + count, ..., 3] = quaternion_w
        view = buffer[:n + count]
        self._buffers[key] = (buffer, view)
        return view

    def remove_row(self, row: int) -> None:
        """Delete one character's row; the rows after it move down by one. Not in the tick.

        This tick's derived arrays (goals, the solver's result, vertebrae) are dropped: the next
        tick makes them again."""
        keep = np.arange(self.n) != row
        for name in _ROW_FIELDS:
            setattr(self, name, getattr(self, name)[keep])
        self.poses = self.poses.take(keep)
        self.posture = None if self.posture is None else self.posture.take(keep)
        self.columns = {name: column[keep] for name, column in self.columns.items()}
        self.vertebrae = self.goals = self.solved = self.clip_positions = None
        self._buffers.clear()


#: The fields that are one array row per character.
_ROW_FIELDS = tuple(f.name for f in fields(CharacterStore)
                    if f.name not in NOT_ROWS and not f.name.startswith("_"))
