"""Steering: characters walk along paths, to goals, or at a heading and speed given each tick.

Paper §4 splits the root into a *global* heading and a *local* oscillation. Steering turns only
the global part: each tick the character's placement (the frame its motion's root path is laid
out from) turns by a small angle about the foot it stands on, so from then on the motion's own
root displacement is integrated rotated by the steered heading, while the pelvis keeps its own
sway and the planted foot stays on its footprint (GroundAdapt keeps the locked footprint; the
turn about it moves the motion's own ankle by nothing). A character with no foot down (a run's
flight) turns about its root.

The speed asked for is met by the playback rate (within :attr:`SteeringSettings.rate_min` ..
``rate_max`` of the clip's own), then by the clip: a character with a locomotion set (``idle``,
``walk``, ``run``) plays the one whose own speed covers the speed asked for, cross-faded at the
middle of a stance of the same foot in both clips (that foot stays locked through the fade), or,
to and from ``idle`` (both feet down), at any moment.

Paths are followed by pure pursuit: the character heads for the point of its path a lookahead
ahead of its progress along it; at the last waypoint it stops on its idle motion. It slows down
for the corners ahead (:func:`corner_speed`) and rounds a sharp one on the arc its turn rate
allows at that speed (the lookahead held short of the corner until the arc begins). A goal behind
it (more than :attr:`SteeringSettings.behind_rad` off its heading) is turned to on the spot: the
slowest steps and the fastest turn.

All per-character state is in the store (``steer_*``, ``path_*``, ``gait*``); :func:`steer` works
on every steered row at once (numpy over rows), called by MotionPlayback before it samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import leg_length
from ecs_anim.core.skeleton import LENGTH_INDEX
from ecs_anim.motion.sampling import ClipBank, frame_position, loop_transform, rotate_xy, wrap_angle
from ecs_anim.runtime.kernels.avoidance import orca_velocities
from ecs_anim.runtime.playback_queue import start_clips
from ecs_anim.runtime.store import CharacterStore

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: ``store.steer_mode``: not steered, heading and speed from code, following a path.
STEER_OFF, STEER_HEADING, STEER_PATH = 0, 1, 2
#: ``store.gait`` and the columns of ``store.gait_clip``.
GAITS = ("idle", "walk", "run")
IDLE, WALK, RUN = 0, 1, 2
CLAVICLE_L, CLAVICLE_R = LENGTH_INDEX["clavicle_l"], LENGTH_INDEX["clavicle_r"]


@dataclass(frozen=True)
class SteeringSettings:
    """How steered characters move (one set per simulation, ``Simulation.steering_settings``).

    rate_min, rate_max : playback rates allowed (1 = the clip as captured); a speed outside
        them picks another clip of the locomotion set, else is held at the limit.
    rate_change_per_s : how fast the playback rate may change (per second).
    max_turn_rad_s : fastest turn while walking or running (rad/s).
    turn_in_place_rad_s : turn rate when the goal is behind (rad/s), at the slowest steps.
    behind_rad : a heading error beyond this turns on the spot.
    lookahead_s, lookahead_min_m : pure pursuit aims this far ahead along the path (seconds at
        the current speed, at least ``lookahead_min_m`` metres).
    corner_tolerance_m : a path's corner is taken slow enough for the turn to stray at most
        this far from the path (m; :func:`corner_speed`), no slower than the slowest steps.
    gait_fade_s : cross-fade between clips of the locomotion set (s).
    contact_release_s : during that fade, a foot that one of the clips lifts leaves its
        footprint over this time (s), not at once.
    run_hysteresis : a run goes back to a walk only below ``rate_max - run_hysteresis`` of the
        walk's own speed (no switching back and forth at the threshold).
    avoidance : steered characters avoid each other (ORCA, :func:`avoid`); False: none does
        (one character is switched off by ``Simulation.set_avoidance``).
    avoid_margin_m : a walker's avoidance radius is its shoulder half-width (its clavicle's
        length: the neck base to the shoulder joint's centre) plus this margin (the arm's flesh
        and swing, the pelvis's sway) (m).
    avoid_time_horizon_s : collisions within this time are avoided (s).
    avoid_neighbours : at most this many nearest walkers are avoided by each.
    avoid_neighbour_m : walkers farther than this are not looked at (m).
    avoid_cone_rad : a walker with neighbours keeps to velocities within this angle of the
        way it goes (at most pi / 2 limits it; the default pi: any, as ORCA).
    avoid_stride_legs, avoid_feet_legs : a walking body's legs sweep a stadium, the points
        within ``avoid_feet_legs`` leg lengths of a segment ``avoid_stride_legs`` leg lengths
        fore and aft of its root along the way it goes (the ankle reaches 0.54 ahead at heel
        strike and 0.57 behind at toe-off; knees and ankles 0.15 to the side, a thigh's
        radius); the segment shrinks to nothing from the slowest steps to standing. Walkers
        keep their stadiums apart as well as their radii (:func:`avoid`).
    """

    rate_min: float = 0.5
    rate_max: float = 1.2
    rate_change_per_s: float = 1.0
    max_turn_rad_s: float = 1.5
    turn_in_place_rad_s: float = 2.0
    behind_rad: float = np.deg2rad(100.0)
    lookahead_s: float = 0.5
    lookahead_min_m: float = 0.4
    gait_fade_s: float = 0.4
    contact_release_s: float = 0.15
    run_hysteresis: float = 0.15
    avoidance: bool = True
    avoid_margin_m: float = 0.1
    avoid_time_horizon_s: float = 2.0
    avoid_neighbours: int = 6
    avoid_neighbour_m: float = 5.0
    avoid_cone_rad: float = float(np.pi)
    avoid_stride_legs: float = 0.6
    avoid_feet_legs: float = 0.25
    corner_tolerance_m: float = 0.15


DEFAULT_STEERING = SteeringSettings()


@dataclass(frozen=True)
class GaitTable:
    """What steering needs to know of each clip of a bank, from its root path and contacts.

    travel_rad : (n_clips,) direction its root travels over a loop, in the clip's own frame
        (radians from +x; the first frame's heading for a clip that stays in place).
    speed_legs_s : (n_clips,) its own root speed over a loop, leg lengths per second.
    mid_stance_s : (n_clips, 2) the middle of each foot's first contact [left, right] (s; NaN
        for a foot never lifted or never down).
    cycle_s : (n_clips,) its gait cycle (s): the clip's duration over the left foot's contacts.
    """

    travel_rad: F64
    speed_legs_s: F64
    mid_stance_s: F64
    cycle_s: F64

    @classmethod
    def from_bank(cls, bank: ClipBank) -> GaitTable:
        n_clips = bank.n_frames.shape[0]
        shift = bank.loop_shift
        duration = bank.duration_s(np.arange(n_clips))
        moves = np.linalg.norm(shift, axis=1) > 1e-6
        first_heading = bank.poses.root_heading[bank.start]
        travel = np.where(moves, np.arctan2(shift[:, 1], shift[:, 0]), first_heading)
        mid = np.full((n_clips, 2), np.nan)
        cycle = np.full(n_clips, np.nan)
        # Contact intervals per clip and foot (load time: a loop over clips is fine here).
        for k in range(n_clips):
            w = bank.contact_weight[bank.start[k]:bank.start[k] + bank.n_frames[k]] > 0.0
            for side in range(2):
                down = w[:, side]
                if down.all() or not down.any():
                    continue
                # Rotate so the clip starts in the air; contacts are then whole runs of frames.
                offset = int(np.argmin(down))
                rolled = np.roll(down, -offset)
                edges = np.diff(rolled.astype(np.int64))
                starts = np.flatnonzero(edges == 1) + 1
                ends = np.flatnonzero(edges == -1) + 1
                if ends.size < starts.size:
                    ends = np.append(ends, rolled.size)
                first = ((starts[0] + ends[0] - 1) / 2 + offset) % bank.n_frames[k]
                mid[k, side] = first / bank.fps[k]
                if side == 0:
                    cycle[k] = duration[k] / starts.size
        return cls(travel, np.linalg.norm(shift, axis=1) / duration, mid, cycle)


def motion_root_xy(bank: ClipBank, st: CharacterStore, rows: I64, fading: bool = False) -> F64:
    """Where each character's motion puts its root this tick, before ground or COM adaptation
    (world xy, metres (r, 2)): its clip's root at its clock, laid out from its placement (with
    ``fading``: the clip being faded out, from its own placement)."""
    if fading:
        clip, time_s, loop = st.fade_clip[rows], st.fade_time_s[rows], st.fade_loop[rows]
        xy, heading = st.fade_placement_xy[rows], st.fade_placement_heading[rows]
    else:
        clip, time_s, loop = st.clip[rows], st.clip_time_s[rows], st.loop[rows]
        xy, heading = st.placement_xy[rows], st.placement_heading[rows]
    i0, i1, w, loops, wraps = frame_position(bank, clip, time_s, loop)
    first = bank.start[clip]
    p0 = bank.poses.root_position[first, :2]

    def at(frame: I64, n_loops: F64) -> F64:
        angle, moved = loop_transform(bank, clip, n_loops)
        return p0 + moved + rotate_xy(bank.poses.root_position[first + frame, :2] - p0, angle)

    before = at(i0, loops)
    root = before + w[:, None] * (at(i1, loops + wraps) - before)
    leg = leg_length(st.lengths[rows])[:, None]
    placed: F64 = rotate_xy(root * leg, heading) + xy
    return placed


def carry_fading_roots(st: CharacterStore, bank: ClipBank,
                       playing: NDArray[np.bool_] | None = None) -> None:
    """Blend root *velocities*, not positions, while a locomotion cross-fade runs: both clips'
    placements are moved so that their roots are at the blend of the two this tick, so each
    then moves on at its own speed and the blend's speed is the blend of theirs. (Blending
    positions would bring a walk fading into idle back to where the fade began.)

    Reads store.fade_s, fade_elapsed_s, fade_keeps_contacts, the clip and fade fields;
    writes placement_xy, fade_placement_xy."""
    carried = (st.fade_s > 0.0) & st.fade_keeps_contacts
    rows = np.flatnonzero(carried if playing is None else carried & playing)
    if rows.size == 0:
        return
    new, old = motion_root_xy(bank, st, rows), motion_root_xy(bank, st, rows, fading=True)
    w = np.clip(st.fade_elapsed_s[rows] / np.maximum(st.fade_s[rows], 1e-9), 0.0, 1.0)[:, None]
    blended = (1.0 - w) * old + w * new
    st.placement_xy[rows] += blended - new
    st.fade_placement_xy[rows] += blended - old


#: Path segments searched each tick for the point nearest the character (from the one its
#: progress, less half a metre, is on).
NEAREST_SEGMENTS = 8


def _path_progress(path: F64, cum_m: F64, rows: I64, count: I64, progress: F64,
                   here: F64) -> tuple[F64, F64]:
    """Arc length along each path of the point nearest ``here`` (r, 2), searched from half a
    metre behind ``progress`` (r,) over :data:`NEAREST_SEGMENTS` segments and at most 2 m
    ahead (so a path crossing itself is not cut short); never less than ``progress``. Returns
    (that arc length (r,), the path's total length (r,)). ``path`` (n, M, 2) the store's paths
    and ``cum_m`` (n, M) the arc length at each point, read at the store ``rows`` (r,), which
    have ``count`` (r,) points (the first: where the character started)."""
    r = rows[:, None]
    last = (count - 2)[:, None]  # the last segment's index
    first = np.sum(cum_m[rows, 1:] < (progress - 0.5)[:, None], axis=1)[:, None]
    k = np.minimum(first + np.arange(NEAREST_SEGMENTS)[None], np.maximum(last, 0))
    a, b = path[r, k], path[r, k + 1]
    seg = b - a
    seg_len = cum_m[r, k + 1] - cum_m[r, k]
    t = np.clip(np.einsum("rmi,rmi->rm", here[:, None] - a, seg)
                / np.maximum(seg_len**2, 1e-12), 0.0, 1.0)
    s = cum_m[r, k] + t * seg_len
    distance = np.linalg.norm(a + t[..., None] * seg - here[:, None], axis=-1)
    distance = np.where(s <= progress[:, None] + 2.0, distance, np.inf)
    best = np.argmin(distance, axis=1)
    i = np.arange(best.size)
    nearest = np.where(np.isfinite(distance[i, best]), s[i, best], progress)
    return np.maximum(progress, nearest), cum_m[rows, count - 1]


def _point_at(path: F64, cum_m: F64, rows: I64, count: I64, arc_m: F64) -> F64:
    """The point (r, 2) at arc length ``arc_m`` (r,) along each path (clamped to its ends);
    arguments as for :func:`_path_progress`."""
    r = rows
    k = np.minimum(np.sum(cum_m[rows, 1:] < arc_m[:, None], axis=1), np.maximum(count - 2, 0))
    length = cum_m[r, k + 1] - cum_m[r, k]
    u = np.clip((arc_m - cum_m[r, k]) / np.maximum(length, 1e-12), 0.0, 1.0)
    point: F64 = path[r, k] + u[:, None] * (path[r, k + 1] - path[r, k])
    return point


#: A corner turning more than this is sharp: the aim does not go past its rounding arc (a
#: smooth curve given as many waypoints, a circle's, is followed by pure pursuit alone).
SHARP_CORNER_RAD = np.deg2rad(30.0)
#: Waypoints looked at ahead of a character's progress for corners to slow down for.
CORNERS_AHEAD = 4


def _corners_ahead(path: F64, cum_m: F64, rows: I64, count: I64, progress: F64) -> tuple[F64, F64]:
    """The next :data:`CORNERS_AHEAD` corners of each path past ``progress`` (r,) m: how far
    along the path each is (r, K) m, and how much the path turns there (r, K) rad, 0 to pi
    (0 past the last waypoint); arguments as for :func:`_path_progress`."""
    r = rows[:, None]
    after = np.sum(cum_m[rows, 1:] <= progress[:, None], axis=1)  # the segment progress is on
    k = (after + 1)[:, None] + np.arange(CORNERS_AHEAD)[None]  # its end, and the next ones
    inner = k <= (count - 2)[:, None]
    k = np.minimum(k, np.maximum(count - 2, 1)[:, None])
    before, at, beyond = path[r, k - 1], path[r, k], path[r, np.minimum(k + 1, path.shape[1] - 1)]
    come, go = at - before, beyond - at
    cos_turn = np.einsum("rki,rki->rk", come, go) / np.maximum(
        np.linalg.norm(come, axis=-1) * np.linalg.norm(go, axis=-1), 1e-12)
    turn = np.where(inner, np.arccos(np.clip(cos_turn, -1.0, 1.0)), 0.0)
    return cum_m[r, k] - progress[:, None], turn


def corner_speed(turn_rad: F64, settings: SteeringSettings) -> F64:
    """The fastest a walker may take a corner turning ``turn_rad`` (...) and stay within
    ``settings.corner_tolerance_m`` of its path (m/s): turning at most ``max_turn_rad_s`` its
    smallest turn has the radius speed / turn rate, and a circle of radius R rounding a corner
    of that turn strays R (1 - cos(turn / 2)) from the path."""
    stray = np.maximum(1.0 - np.cos(0.5 * turn_rad), 1e-9)
    fastest: F64 = settings.max_turn_rad_s * settings.corner_tolerance_m / stray
    return fastest


def turn_rate_limit(rate: F64, settings: SteeringSettings) -> F64:
    """The fastest a walker may turn (rad/s) at playback ``rate`` (...): ``max_turn_rad_s`` at
    the clip's own rate and above, rising to ``turn_in_place_rad_s`` at the slowest steps
    (``rate_min``), as for a goal behind."""
    limit: F64 = np.interp(rate, [settings.rate_min, 1.0],
                           [settings.turn_in_place_rad_s, settings.max_turn_rad_s])
    return limit


def steer(st: CharacterStore, bank: ClipBank, gaits: GaitTable, settings: SteeringSettings,
          dt: float, playing: NDArray[np.bool_] | None = None,
          not_avoiding: I64 | None = None) -> None:
    """One tick of steering for every steered character (``store.steer_mode > 0``), all at once:
    path progress and the heading and speed wanted, the clip of the locomotion set to play (a
    cross-fade started at matching foot phases), the playback rate, and the turn of the
    placement about the planted foot.

    Reads store.steer_*, path_* (path_cum_m the arc lengths), gait, gait_clip, clip, clip_time_s, loop, speed, fade_s,
    placement_*, lengths, contact_weight, locked, footprint (the last tick's). Writes
    steer_mode, steer_heading_rad, steer_speed_m_s (a path's end: stopped), path_progress_m,
    gait, speed, placement_*, fade_placement_* (also :func:`carry_fading_roots`), and through
    :func:`~ecs_anim.runtime.playback_queue.start_clips` the fade and clip fields.
    ``playing`` (n,) bool: the characters MotionPlayback plays (None: all); the others are not
    steered. With ``settings.avoidance`` the heading and speed wanted are then those of
    :func:`avoid`, but for the entities ``not_avoiding`` (entity ids).
    """
    carry_fading_roots(st, bank, playing)
    steered = st.steer_mode > STEER_OFF
    rows = np.flatnonzero(steered if playing is None else steered & playing)
    if rows.size == 0:
        return
    leg = leg_length(st.lengths[rows])
    here = motion_root_xy(bank, st, rows)
    clip = st.clip[rows]
    travel = wrap_angle(st.placement_heading[rows] + gaits.travel_rad[clip])
    own_walk = gaits.speed_legs_s[st.gait_clip[rows, WALK]] * leg
    speed_now = st.speed[rows] * gaits.speed_legs_s[clip] * leg
    wanted_speed = np.where(np.isnan(st.steer_speed_m_s[rows]), own_walk, st.steer_speed_m_s[rows])
    wanted_heading = st.steer_heading_rad[rows].copy()
    # How far ahead pure pursuit aims (m; NaN: at the current speed's lookahead).
    pursuit_m = np.full(rows.size, np.nan)

    # Paths: progress, the lookahead point, the end.
    on_path = st.steer_mode[rows] == STEER_PATH
    if on_path.any():
        p = rows[on_path]
        count = st.path_len[p]
        progress, total = _path_progress(st.path_xy, st.path_cum_m, p, count,
                                         st.path_progress_m[p], here[on_path])
        st.path_progress_m[p] = progress
        # Corners: each is rounded on the arc of the turn rate at the speed it is taken at
        # (slow enough to stray at most corner_tolerance_m), tangent length ``rounding`` m
        # before and after it. The walker brakes (as fast as the playback rate may change) to
        # be at that speed when its aim reaches that arc, and its aim does not go past it.
        ahead_m, turn = _corners_ahead(st.path_xy, st.path_cum_m, p, count, progress)
        walk_own = own_walk[on_path][:, None]
        at_corner = np.clip(corner_speed(turn, settings), settings.rate_min * walk_own,
                            wanted_speed[on_path][:, None])
        radius = at_corner / turn_rate_limit(at_corner / walk_own, settings)
        # (A U-turn's arc would start infinitely far ahead: 150 degrees at most.)
        rounding = radius * np.tan(0.5 * np.minimum(turn, np.deg2rad(150.0)))
        brake = settings.rate_change_per_s * walk_own
        slack = np.maximum(ahead_m - rounding - settings.lookahead_min_m, 0.0)
        allowed = np.sqrt(at_corner**2 + 2.0 * brake * slack)
        wanted_speed[on_path] = np.minimum(wanted_speed[on_path], allowed.min(axis=1))
        lookahead = np.maximum(settings.lookahead_s * np.maximum(speed_now[on_path], 0.0),
                               settings.lookahead_min_m)
        # Before a sharp corner's arc the aim stays short of the corner; on the arc it sits at
        # the arc's far end.
        sharp = turn[:, 0] > SHARP_CORNER_RAD
        to_corner = ahead_m[:, 0]
        near = to_corner <= rounding[:, 0]
        held = np.where(near, to_corner + rounding[:, 0], np.minimum(lookahead, to_corner))
        lookahead = np.where(sharp, held, lookahead)
        aim = _point_at(st.path_xy, st.path_cum_m, p, count,
                        np.minimum(progress + lookahead, total))
        end = st.path_xy[p, count - 1]
        to_end = np.linalg.norm(end - here[on_path], axis=1)
        to_aim = aim - here[on_path]
        # Rounding a corner, the turn follows the circle through the aim (pure pursuit's own
        # curvature, 2 sin(error) / distance to the aim).
        pursuit_m[on_path] = np.where(sharp & near, np.linalg.norm(to_aim, axis=1), np.nan)
        wanted_heading[on_path] = np.where(np.linalg.norm(to_aim, axis=1) > 1e-6,
                                           np.arctan2(to_aim[:, 1], to_aim[:, 0]), travel[on_path])
        # A walker still turning (a corner just passed) goes as slow as that turn asks: from on
        # its path, turning by a (its heading against the way its path goes where it is, over
        # the next 5 cm) strays as far as rounding a corner of 2 a, never below the slowest
        # steps (a walker standing would not turn).
        way = (_point_at(st.path_xy, st.path_cum_m, p, count, np.minimum(progress + 0.05, total))
               - _point_at(st.path_xy, st.path_cum_m, p, count, progress))
        still_to_turn = np.where(np.linalg.norm(way, axis=1) > 1e-6, np.abs(wrap_angle(
            np.arctan2(way[:, 1], way[:, 0]) - travel[on_path])), 0.0)
        turning = np.maximum(corner_speed(2.0 * still_to_turn, settings),
                             settings.rate_min * own_walk[on_path])
        wanted_speed[on_path] = np.minimum(wanted_speed[on_path], turning)
        # Stop where a fade to idle, started now, ends on the last waypoint (the pelvis slows
        # linearly over the fade: half the fade at the current speed).
        remaining = np.maximum(total - progress, to_end)
        arrived = (progress + lookahead >= total) & (
            (remaining <= speed_now[on_path] * settings.gait_fade_s / 2) | (remaining < 0.05))
        if arrived.any():
            done = p[arrived]
            st.path_progress_m[done] = total[arrived]  # at its end: arrived (an event)
            st.steer_mode[done] = STEER_HEADING
            st.steer_speed_m_s[done] = 0.0
            st.steer_heading_rad[done] = travel[on_path][arrived]
            wanted_heading[np.flatnonzero(on_path)[arrived]] = travel[on_path][arrived]
            wanted_speed[np.flatnonzero(on_path)[arrived]] = 0.0
    if settings.avoidance:
        wanted_heading, wanted_speed = avoid(st, settings, rows, here, travel, speed_now,
                                             own_walk, wanted_heading, wanted_speed,
                                             not_avoiding, dt)
    error = wrap_angle(wanted_heading - travel)
    behind = (np.abs(error) > settings.behind_rad) & (wanted_speed > 0.0)
    # The slowest steps while turning on the spot.
    wanted_speed = np.where(behind, settings.rate_min * own_walk, wanted_speed)

    _choose_gaits(st, bank, gaits, settings, rows, wanted_speed, leg, dt)

    # Playback rate of the clip now playing, changed gradually.
    clip = st.clip[rows]
    own = gaits.speed_legs_s[clip] * leg
    moving = st.gait[rows] != IDLE
    rate = np.where(moving, np.clip(wanted_speed / np.maximum(own, 1e-9), settings.rate_min,
                                    settings.rate_max), 1.0)
    step = settings.rate_change_per_s * dt
    st.speed[rows] = np.clip(rate, st.speed[rows] - step, st.speed[rows] + step)

    # Turn: pure pursuit's curvature at the current speed, within the turn-rate limits; on the
    # spot when the goal is behind. A standing character (idle) does not turn.
    speed_now = st.speed[rows] * own
    lookahead = np.where(np.isnan(pursuit_m), np.maximum(
        settings.lookahead_s * speed_now, settings.lookahead_min_m), np.maximum(pursuit_m, 0.05))
    fastest = turn_rate_limit(st.speed[rows] * own / np.maximum(own_walk, 1e-9), settings)
    turn_rate = np.clip(2.0 * speed_now * np.sin(error) / lookahead, -fastest, fastest)
    turn_rate = np.where(behind, np.sign(error) * settings.turn_in_place_rad_s, turn_rate)
    turn = np.where(moving, turn_rate * dt, 0.0)
    turn = np.sign(turn) * np.minimum(np.abs(turn), np.abs(error))
    _turn_placements(st, rows, turn, here)


def avoidance_radius(lengths: F64, settings: SteeringSettings) -> F64:
    """Each body's avoidance radius (m): its shoulder half-width (the mean of its clavicles'
    lengths, neck base to shoulder joint centre) plus ``settings.avoid_margin_m``.
    ``lengths`` (..., N_LENGTHS) m -> (...)."""
    shoulder: F64 = 0.5 * (lengths[..., CLAVICLE_L] + lengths[..., CLAVICLE_R])
    return shoulder + settings.avoid_margin_m


def avoid(st: CharacterStore, settings: SteeringSettings, rows: I64, here: F64, travel: F64,
          speed_now: F64, own_walk: F64, wanted_heading: F64, wanted_speed: F64,
          not_avoiding: I64 | None, dt: float) -> tuple[F64, F64]:
    """Local avoidance between the steered characters ``rows`` (r,): the heading (rad) and speed
    (m/s) (each (r,)) that keep them apart, by ORCA
    (:func:`ecs_anim.runtime.kernels.avoidance.orca_velocities`) over all of them at once.

    Each is an agent at its motion's root ``here`` (r, 2) m, moving at ``speed_now`` along
    ``travel`` (r,), that would go at ``wanted_speed`` along ``wanted_heading`` (its path's pure
    pursuit, or the heading and speed given), no faster, with the radius of
    :func:`avoidance_radius`, its legs the stadium of ``settings.avoid_stride_legs`` and
    ``avoid_feet_legs`` (``own_walk`` (r,) m/s, the walk's own speed: the stride shrinks below
    the slowest steps), and no slower than its slowest steps but standing. A character asked
    to stand (speed 0: at its path's end) or among the entities ``not_avoiding`` keeps what
    it wanted and is avoided by the others in full."""
    heading_unit = np.stack([np.cos(wanted_heading), np.sin(wanted_heading)], axis=1)
    travel_unit = np.stack([np.cos(travel), np.sin(travel)], axis=1)
    active = wanted_speed > 0.0
    if not_avoiding is not None and not_avoiding.size:
        active &= ~np.isin(st.entity[rows], not_avoiding)
    leg = leg_length(st.lengths[rows])
    striding = np.clip(speed_now / np.maximum(settings.rate_min * own_walk, 1e-9), 0.0, 1.0)
    velocity = orca_velocities(
        here, speed_now[:, None] * travel_unit, wanted_speed[:, None] * heading_unit,
        avoidance_radius(st.lengths[rows], settings), wanted_speed, active,
        range_m=settings.avoid_neighbour_m, time_horizon_s=settings.avoid_time_horizon_s,
        max_neighbours=settings.avoid_neighbours, dt=dt, facing=travel_unit,
        cone_rad=settings.avoid_cone_rad, stride_m=settings.avoid_stride_legs * leg * striding,
        feet_m=settings.avoid_feet_legs * leg,
        min_speed=np.minimum(settings.rate_min * own_walk, wanted_speed))
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    heading = np.where(speed > 1e-6, np.arctan2(velocity[:, 1], velocity[:, 0]), wanted_heading)
    # A velocity behind it (away from a walker too close) would be turned to on the spot with
    # steps forward, into the other: it waits instead (unless its own way is behind it).
    behind = ((np.abs(wrap_angle(heading - travel)) > settings.behind_rad)
              & (np.abs(wrap_angle(wanted_heading - travel)) <= settings.behind_rad))
    speed = np.where(behind, 0.0, speed)
    return np.where(active, heading, wanted_heading), np.where(active, speed, wanted_speed)


def _choose_gaits(st: CharacterStore, bank: ClipBank, gaits: GaitTable,
                  settings: SteeringSettings, rows: I64, wanted_speed: F64, leg: F64,
                  dt: float) -> None:
    """Start the clip of the locomotion set that the speed asks for, where it differs from the
    one playing, no fade is running, and the phase matches (see the module docstring)."""
    clips = st.gait_clip[rows]
    walk_own = gaits.speed_legs_s[clips[:, WALK]] * leg
    has_idle, has_run = clips[:, IDLE] >= 0, clips[:, RUN] >= 0
    current = st.gait[rows]
    run_from = settings.rate_max * walk_own
    run_until = (settings.rate_max - settings.run_hysteresis) * walk_own
    wanted = np.where(has_run & ((wanted_speed > run_from)
                                 | ((current == RUN) & (wanted_speed > run_until))), RUN, WALK)
    wanted = np.where(has_idle & (wanted_speed <= 0.5 * settings.rate_min * walk_own), IDLE, wanted)
    change = (wanted != current) & (st.fade_s[rows] == 0.0)
    if not change.any():
        return
    r, old_gait, new_gait = rows[change], current[change], wanted[change]
    old_clip = st.clip[r]
    new_clip = clips[change][np.arange(r.size), new_gait]
    time = st.clip_time_s[r]
    step = dt * st.speed[r]
    # Phase offset past each foot's middle of stance in the clip now playing.
    cycle_old = gaits.cycle_s[old_clip]
    past = (time[:, None] - gaits.mid_stance_s[old_clip]) % cycle_old[:, None]
    crossed = past < step[:, None]  # that foot's mid-stance was passed during the last tick
    foot = np.argmax(crossed, axis=1)
    at_phase = crossed.any(axis=1)
    # To or from idle (both feet down) any moment does; the walk starts at its left mid-stance.
    free = (old_gait == IDLE) | (new_gait == IDLE)
    go = at_phase | free
    if not go.any():
        return
    pick = np.arange(r.size)
    new_cycle = gaits.cycle_s[new_clip]
    matched = (gaits.mid_stance_s[new_clip, foot]
               + past[pick, foot] * new_cycle / np.where(np.isnan(cycle_old), 1.0, cycle_old))
    start = np.where(new_gait == IDLE, 0.0,
                     np.where(old_gait == IDLE, gaits.mid_stance_s[new_clip, 0], matched))
    start = np.where(np.isfinite(start), start, 0.0)
    r, start, new_clip, new_gait = r[go], start[go], new_clip[go], new_gait[go]
    start_clips(st, bank, r, new_clip, start, np.full(r.size, settings.gait_fade_s),
                np.ones(r.size, bool), keep_contacts=True)
    # The new clip starts at the rate that keeps the root's speed (idle: as captured).
    same_speed = st.speed[r] * gaits.speed_legs_s[old_clip[go]] / np.maximum(
        gaits.speed_legs_s[new_clip], 1e-9)
    st.speed[r] = np.where(new_gait == IDLE, 1.0,
                           np.clip(same_speed, settings.rate_min, settings.rate_max))
    st.gait[r] = new_gait


def _turn_placements(st: CharacterStore, rows: I64, turn: F64, root_xy: F64) -> None:
    """Turn each character's placement (and the fading clip's) by ``turn`` (r,) radians about
    the feet it stands on (its locked footprints, weighted by their contact), or about its root
    ``root_xy`` (r, 2) when no foot is down."""
    w = st.contact_weight[rows] * st.locked[rows]
    support = w.sum(axis=1)
    feet = np.einsum("rs,rsi->ri", w, st.footprint[rows, :, :2]) / np.maximum(support, 1e-9)[:, None]
    pivot = np.where((support > 0.0)[:, None], feet, root_xy)
    for xy, heading in ((st.placement_xy, st.placement_heading),
                        (st.fade_placement_xy, st.fade_placement_heading)):
        xy[rows] = pivot + rotate_xy(xy[rows] - pivot, turn)
        heading[rows] = heading[rows] + turn
