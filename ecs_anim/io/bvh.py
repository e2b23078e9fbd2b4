"""BVH reading (any channel order, 3 or 6 channels on any joint, End Sites) and writing.

Reading gives a :class:`BvhSkeleton` (hierarchy, offsets, channels) and the motion as a
(n_frames, n_channels) array; :func:`forward_kinematics` turns both into global joint positions
and orientations for all frames at once (the only Python loop is over joints, in topological
order). Positions stay in the file's own axes and units here; :mod:`ecs_anim.io.importing` converts
them to metres, Z up.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, quoted
from ecs_anim.core.files import read_text
from ecs_anim.core.rotations import euler_to_matrix

F64 = NDArray[np.float64]

MIN_FRAME_TIME_S = 1e-4
MAX_FRAME_TIME_S = 10.0
MAX_DEPTH = 200  # deeper hierarchies are refused rather than overflowing the parser's recursion

_ROTATION_CHANNELS = {"xrotation": "X", "yrotation": "Y", "zrotation": "Z"}
_POSITION_CHANNELS = {"xposition": 0, "yposition": 1, "zposition": 2}


@dataclass
class BvhJoint:
    """One BVH joint or End Site.

    ``offset`` is in file units and axes, shape (3,). ``channels`` are the names as written.
    End Sites are stored as joints named ``<parent>.end`` with no channels.
    """

    name: str
    parent: int
    offset: F64
    channels: list[str] = field(default_factory=list)
    is_end_site: bool = False
    line: int = 0


@dataclass
class BvhSkeleton:
    """A parsed BVH hierarchy; joints in file (topological) order."""

    joints: list[BvhJoint]
    path: str = "<bvh>"

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    def children(self, index: int) -> list[int]:
        return [i for i, j in enumerate(self.joints) if j.parent == index]

    @property
    def n_channels(self) -> int:
        return sum(len(j.channels) for j in self.joints)


def rate_of_step(frame_time_s: float) -> float:
    """Frames per second of a frame time (s): a rate within 0.05 % of a whole number is taken
    as it (writers round the frame time: ``0.008333`` for 120 Hz)."""
    rate = 1.0 / frame_time_s
    whole = round(rate)
    return float(whole) if whole > 0 and abs(rate - whole) <= 5e-4 * whole else rate


@dataclass
class BvhMotion:
    """A BVH file's content: skeleton, per-frame channel values (file units, degrees), timing."""

    skeleton: BvhSkeleton
    channels: F64  # (n_frames, n_channels)
    frame_time_s: float
    #: One-line notes on what was tolerated while reading (``file:line: ...``), e.g. one frame
    #: line more than ``Frames:`` announces.
    warnings: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return int(self.channels.shape[0])

    @property
    def fps(self) -> float:
        """Frames per second. Writers round the frame time (``0.008333`` for 120 Hz,
        ``0.03333333`` for 30 Hz), so a rate within 0.05 % of a whole number is taken as it."""
        return rate_of_step(self.frame_time_s)


class _Lines:
    """Token reader over a text, keeping 1-based line numbers for error messages."""

    def __init__(self, text: str, path: str):
        # Split on newlines only (str.splitlines also breaks at form feeds and other controls,
        # which would shift line numbers); tolerate a byte-order mark and CRLF.
        self.lines = text.lstrip("\ufeff").replace("\r\n", "\n").replace("\r", "\n").split("\n")
        if self.lines and self.lines[-1] == "":
            self.lines.pop()  # the final newline ends the last line; it starts no new one
        self.path = path
        self.row = 0  # index of the next line to read

    def next_tokens(self, expected: str) -> tuple[list[str], int]:
        while self.row < len(self.lines):
            tokens = self.lines[self.row].split()
            self.row += 1
            if tokens:
                return tokens, self.row
        raise InputError(self.path, f"unexpected end of file: expected {expected}",
                         len(self.lines) or 1)


#: Largest magnitude of a BVH number (offsets, positions, angles); beyond it the file is wrong.
MAX_VALUE = 1e7


def _floats(tokens: list[str], count: int, path: str, line: int, what: str) -> F64:
    if len(tokens) != count:
        raise InputError(path, f"{what}: expected {count} numbers, found {len(tokens)}", line)
    try:
        values = np.array([float(t) for t in tokens])
    except ValueError:
        bad = next(t for t in tokens if not _is_number(t))
        raise InputError(path, f"{what}: expected a number, found {quoted(bad)}",
                         line) from None
    _require_plain(tokens, path, line, what)
    if not np.all(np.isfinite(values)):
        raise InputError(path, f"{what}: values must be finite, found {quoted(' '.join(tokens), 60)}", line)
    if np.any(np.abs(values) > MAX_VALUE):
        raise InputError(path, f"{what}: values beyond {MAX_VALUE:g} (a length unit of "
                               f"millimetres would make that 10 km), found {quoted(' '.join(tokens), 60)}", line)
    return values


_ASCII_INT = re.compile(r"[0-9]+")


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _is_plain(text: str) -> bool:
    """Whether ``text`` can only hold numbers as BVH writes them: ASCII without underscores.
    Python's ``float`` also reads ``1_000``, Arabic-Indic ``١٢.٥`` and full-width ``１２``, and
    ``str.split`` splits at non-ASCII spaces; no BVH writer produces those."""
    return text.isascii() and "_" not in text


def _require_plain(tokens: list[str], path: str, line: int, what: str) -> None:
    """Raise :class:`InputError` at ``line`` naming the first number of ``tokens`` (already known
    to read as numbers) written otherwise than in ASCII digits."""
    bad = next((t for t in tokens if not _is_plain(t)), None)
    if bad is not None:
        raise InputError(path, f"{what}: expected a number in ASCII digits (no '_' separators), "
                               f"found {quoted(bad)}", line)


def read_bvh(path: str | Path) -> BvhMotion:
    """Read a BVH file. Raises :class:`InputError` (with file and line) on any malformation."""
    return parse_bvh(read_text(path), str(path))


def parse_bvh(text: str, path: str = "<bvh>") -> BvhMotion:
    """Parse BVH text; see :func:`read_bvh`."""
    reader = _Lines(text, path)
    tokens, line = reader.next_tokens("HIERARCHY")
    if tokens[0].upper() != "HIERARCHY":
        raise InputError(path, "expected 'HIERARCHY' at the start of a BVH file, found "
                               f"{quoted(tokens[0])}", line)
    joints: list[BvhJoint] = []
    tokens, line = reader.next_tokens("ROOT")
    if tokens[0].upper() != "ROOT" or len(tokens) < 2:
        raise InputError(path, "expected 'ROOT <name>'", line)
    _parse_joint(reader, joints, " ".join(tokens[1:]), -1, line, is_end=False)
    warnings = _rename_duplicate_names(joints, path)

    tokens, line = reader.next_tokens("MOTION")
    if tokens[0].upper() != "MOTION":
        raise InputError(path, f"expected 'MOTION' after the hierarchy, found {quoted(' '.join(tokens), 60)}",
                         line)
    tokens, frames_line = reader.next_tokens("'Frames: N'")
    if tokens[0].lower() != "frames:" or len(tokens) != 2 or not _ASCII_INT.fullmatch(tokens[1]):
        raise InputError(path, f"expected 'Frames: <count>', found {quoted(' '.join(tokens), 60)}", frames_line)
    n_frames = int(tokens[1])
    tokens, line = reader.next_tokens("'Frame Time: T'")
    if [t.lower() for t in tokens[:2]] != ["frame", "time:"] or len(tokens) != 3:
        raise InputError(path, f"expected 'Frame Time: <seconds>', found {quoted(' '.join(tokens), 60)}", line)
    try:
        frame_time = float(tokens[2])
    except ValueError:
        raise InputError(path, f"Frame Time must be a number, found {quoted(tokens[2])}",
                         line) from None
    _require_plain(tokens[2:], path, line, "Frame Time")
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise InputError(path, f"Frame Time must be a positive number of seconds, found {tokens[2]}",
                         line)
    if not MIN_FRAME_TIME_S <= frame_time <= MAX_FRAME_TIME_S:
        raise InputError(path, f"Frame Time {tokens[2]} s is outside {MIN_FRAME_TIME_S:g}.."
                               f"{MAX_FRAME_TIME_S:g} s (0.1 Hz to 10 kHz)", line)
    if n_frames == 0:
        raise InputError(path, "the MOTION section has no frames (Frames: 0)", frames_line)

    skeleton = BvhSkeleton(joints, path)
    n_channels = skeleton.n_channels
    first_data_row = reader.row
    rows = [(i, ln) for i, ln in enumerate(reader.lines[first_data_row:], start=first_data_row + 1)
            if ln.strip()]
    if len(rows) < n_frames:
        last = rows[-1][0] if rows else first_data_row
        raise InputError(path, f"file ends after {len(rows)} of {n_frames} frames "
                               "(truncated? 'Frames:' promises more)", last)
    if len(rows) == n_frames + 1:
        # Some writers count the frames after a first (rest) frame line; Blender and bvhio read
        # every line. More than one extra line is no such off-by-one: refused below.
        warnings.append(f"{path}:{frames_line}: 'Frames:' says {n_frames} but there are "
                        f"{len(rows)} frame lines; read all {len(rows)}")
        n_frames = len(rows)
    if len(rows) > n_frames:
        raise InputError(path, f"found {len(rows)} frame lines but 'Frames:' says {n_frames}",
                         rows[n_frames][0])
    split_rows = [ln.split() for _, ln in rows]
    for (line_no, _), tokens in zip(rows, split_rows, strict=True):
        if len(tokens) != n_channels:
            raise InputError(path, f"frame line has {len(tokens)} values, expected {n_channels} "
                                   "(one per channel of the hierarchy)", line_no)
    flat = [tok for tokens in split_rows for tok in tokens]
    try:
        values = np.array(flat, dtype=np.float64).reshape(n_frames, n_channels)
    except ValueError:
        for line_no, ln in rows:
            for tok in ln.split():
                if not _is_number(tok):
                    raise InputError(path, f"expected a number, found {quoted(tok)}",
                                     line_no) from None
        raise
    # One pass over all the frame text; only a file that fails it is searched line by line.
    if not _is_plain("".join(ln for _, ln in rows)):
        _reject_unplain_frame(rows, split_rows, path)
    bad = ~np.isfinite(values) | (np.abs(values) > MAX_VALUE)
    if bad.any():
        frame = int(np.argmax(bad.any(axis=1)))
        col = int(np.argmax(bad[frame]))
        name, channel = _channel_owner(skeleton, col)
        what = "non-finite value" if not np.isfinite(values[frame, col]) else \
            f"value beyond {MAX_VALUE:g}:"
        raise InputError(path, f"{what} {values[frame, col]} in channel {channel} of "
                               f"joint {quoted(name)} (frame {frame + 1} of {n_frames})", rows[frame][0])
    return BvhMotion(skeleton, values, frame_time, warnings)


def _rename_duplicate_names(joints: list[BvhJoint], path: str) -> list[str]:
    """Rename each joint whose name an earlier joint has (``Spine`` -> ``Spine#2``), in place,
    and return one warning per rename: the joint map finds bones by name, and must not take
    the second for the first silently (rigs with extra bones do repeat names; the file is
    still read)."""
    first_line: dict[str, int] = {}
    count: dict[str, int] = {}
    warnings = []
    for joint in joints:
        if joint.is_end_site:  # named after its joint (parents come first: already renamed)
            joint.name = f"{joints[joint.parent].name}.end"
            continue
        if joint.name in first_line:
            count[joint.name] = count.get(joint.name, 1) + 1
            renamed = f"{joint.name}#{count[joint.name]}"
            warnings.append(f"{path}:{joint.line}: joint name {quoted(joint.name)} is used again "
                            f"(first at line {first_line[joint.name]}); read as {quoted(renamed)}")
            joint.name = renamed
        first_line.setdefault(joint.name, joint.line)
    return warnings


def _reject_unplain_frame(rows: list[tuple[int, str]], split_rows: list[list[str]],
                          path: str) -> None:
    """Raise :class:`InputError` at the first frame line holding a non-ASCII character or '_'."""
    for (line_no, ln), tokens in zip(rows, split_rows, strict=True):
        if not _is_plain(ln):
            _require_plain(tokens, path, line_no, "frame line")
            char = next(c for c in ln if not _is_plain(c))  # a non-ASCII space between numbers
            raise InputError(path, f"frame line: numbers must be separated by ASCII spaces or "
                                   f"tabs, found {quoted(char)} (U+{ord(char):04X})", line_no)


def _channel_owner(skeleton: BvhSkeleton, column: int) -> tuple[str, str]:
    for j in skeleton.joints:
        if column < len(j.channels):
            return j.name, j.channels[column]
        column -= len(j.channels)
    return "?", "?"


def _parse_joint(reader: _Lines, joints: list[BvhJoint], name: str, parent: int, line: int,
                 is_end: bool) -> None:
    path = reader.path
    tokens, brace_line = reader.next_tokens("'{'")
    if tokens != ["{"]:
        raise InputError(path, f"expected '{{' after {quoted(name)}, found {quoted(' '.join(tokens), 60)}",
                         brace_line)
    tokens, off_line = reader.next_tokens("OFFSET")
    if tokens[0].upper() != "OFFSET":
        raise InputError(path, f"expected 'OFFSET x y z' in {quoted(name)}, found {quoted(tokens[0])}", off_line)
    offset = _floats(tokens[1:], 3, path, off_line, f"OFFSET of {quoted(name)}")
    index = len(joints)
    depth = 0
    p = parent
    while p >= 0:
        depth, p = depth + 1, joints[p].parent
    if depth > MAX_DEPTH:
        raise InputError(path, f"hierarchy nested more than {MAX_DEPTH} joints deep at {quoted(name)}",
                         line)
    joint = BvhJoint(name=name, parent=parent, offset=offset, is_end_site=is_end, line=line)
    joints.append(joint)
    if is_end:
        tokens, close_line = reader.next_tokens("'}'")
        if tokens != ["}"]:
            raise InputError(path, f"expected '}}' closing End Site of {quoted(joints[parent].name)}",
                             close_line)
        return
    tokens, ch_line = reader.next_tokens("CHANNELS")
    if tokens[0].upper() == "CHANNELS":
        if len(tokens) < 2 or not _ASCII_INT.fullmatch(tokens[1]):
            raise InputError(path, f"expected 'CHANNELS <count> <names...>' in {quoted(name)}", ch_line)
        count = int(tokens[1])
        names = tokens[2:]
        if len(names) != count:
            raise InputError(path, f"CHANNELS of {quoted(name)} announces {count} channels but lists "
                                   f"{len(names)}", ch_line)
        seen: set[str] = set()
        for ch in names:
            key = ch.lower()
            if key not in _ROTATION_CHANNELS and key not in _POSITION_CHANNELS:
                raise InputError(path, f"unknown channel {quoted(ch)} in {quoted(name)} (expected X/Y/Z "
                                       "position or rotation)", ch_line)
            if key in seen:
                raise InputError(path, f"channel {quoted(ch)} appears twice in {quoted(name)}", ch_line)
            seen.add(key)
        joint.channels = names
        tokens, ch_line = reader.next_tokens("JOINT, End Site or '}'")
    while True:
        head = tokens[0].upper()
        if head == "JOINT" and len(tokens) >= 2:
            _parse_joint(reader, joints, " ".join(tokens[1:]), index, ch_line, is_end=False)
        elif head == "END" and len(tokens) >= 2 and tokens[1].upper() == "SITE":
            _parse_joint(reader, joints, f"{name}.end", index, ch_line, is_end=True)
        elif tokens == ["}"]:
            return
        elif head == "MOTION":
            raise InputError(path, f"joint {quoted(name)} is not closed with '}}' before MOTION", ch_line)
        else:
            raise InputError(path, f"expected JOINT, End Site or '}}' in {quoted(name)}, found "
                                   f"{quoted(' '.join(tokens), 60)}", ch_line)
        tokens, ch_line = reader.next_tokens(f"'}}' closing {quoted(name)}")


def joint_local_transforms(motion: BvhMotion) -> tuple[F64, F64]:
    """Per-joint local rotations and translations for every frame.

    Returns ``rotations`` (n_frames, n_joints, 3, 3) and ``translations`` (n_frames, n_joints, 3)
    in file units. Position channels *replace* the OFFSET component they name (the common
    convention: Bandai's every-joint position channels equal the OFFSET, and a root's position
    channels give its absolute position).
    """
    skeleton = motion.skeleton
    n_frames = motion.n_frames
    n_joints = len(skeleton.joints)
    rotations = np.broadcast_to(np.eye(3), (n_frames, n_joints, 3, 3)).copy()
    translations = np.empty((n_frames, n_joints, 3))
    column = 0
    for j, joint in enumerate(skeleton.joints):
        translations[:, j] = joint.offset
        rot_cols: list[int] = []
        order = ""
        for ch in joint.channels:
            key = ch.lower()
            if key in _POSITION_CHANNELS:
                translations[:, j, _POSITION_CHANNELS[key]] = motion.channels[:, column]
            else:
                rot_cols.append(column)
                order += _ROTATION_CHANNELS[key]
            column += 1
        if rot_cols:
            # Axes without a channel rotate by zero; append them so the order names all three.
            missing = [a for a in "XYZ" if a not in order]
            angles = np.zeros((n_frames, 3))
            angles[:, : len(rot_cols)] = motion.channels[:, rot_cols]
            rotations[:, j] = euler_to_matrix(angles, order + "".join(missing))
    return rotations, translations


def forward_kinematics(motion: BvhMotion) -> tuple[F64, F64]:
    """Global joint orientations and positions of every joint for all frames (file axes/units).

    Returns ``joint2file`` (n_frames, n_joints, 3, 3) and ``positions`` (n_frames, n_joints, 3).
    End Sites get their parent's orientation.

    A non-root joint's three position channels usually replace its OFFSET (Bandai writes the
    OFFSET itself there); some writers store the joint's position in the file's frame instead
    (an ASF-converted rig's thorax and head). Which one is read from the numbers: the reading
    whose distance to the parent stays closer to the OFFSET's length (median over the frames).
    Orientations chain through the hierarchy either way.
    """
    local_rot, local_pos = joint_local_transforms(motion)
    n_frames, n_joints = local_pos.shape[:2]
    joint2file = np.empty((n_frames, n_joints, 3, 3))
    positions = np.empty((n_frames, n_joints, 3))
    for j, joint in enumerate(motion.skeleton.joints):
        p = joint.parent
        if p < 0:
            joint2file[:, j] = local_rot[:, j]
            positions[:, j] = local_pos[:, j]
            continue
        joint2file[:, j] = joint2file[:, p] @ local_rot[:, j]
        if _positions_in_file_frame(joint, local_pos[:, j], positions[:, p]):
            positions[:, j] = local_pos[:, j]
        else:
            positions[:, j] = positions[:, p] + np.einsum("fab,fb->fa", joint2file[:, p],
                                                          local_pos[:, j])
    return joint2file, positions


def _positions_in_file_frame(joint: BvhJoint, translation: F64, parent_positions: F64) -> bool:
    """Whether a non-root joint's position channels hold its position in the file's frame:
    ``translation`` (n_frames, 3) read as such stays nearer the OFFSET's length from
    ``parent_positions`` (n_frames, 3) than read as the offset from the parent."""
    names = {ch.lower() for ch in joint.channels}
    if not set(_POSITION_CHANNELS) <= names:
        return False
    length = float(np.linalg.norm(joint.offset))
    as_offset = float(np.median(np.abs(np.linalg.norm(translation, axis=1) - length)))
    as_position = float(np.median(np.abs(np.linalg.norm(translation - parent_positions, axis=1)
                                         - length)))
    return as_offset > 0.25 * length and as_position < 0.5 * as_offset


def rest_positions(skeleton: BvhSkeleton) -> F64:
    """Joint positions with every rotation zero and translations equal to OFFSETs. (n_joints, 3)."""
    out = np.zeros((len(skeleton.joints), 3))
    for j, joint in enumerate(skeleton.joints):
        out[j] = joint.offset if joint.parent < 0 else out[joint.parent] + joint.offset
    return out


# ---------------------------------------------------------------------------------------------
# Writing

@dataclass
class BvhWriteJoint:
    """A joint to write: name, parent index (-1 root), OFFSET (3,), End Site offset or None."""

    name: str
    parent: int
    offset: F64
    end_site: F64 | None = None


_NAME_OK = re.compile(r"^\S+$")


def format_bvh(joints: list[BvhWriteJoint], root_positions: F64, euler_deg: F64,
               frame_time_s: float, order: str = "ZXY", decimals: int = 6,
               translations: dict[int, F64] | None = None) -> str:
    """BVH text: root with 6 channels, every other joint 3 rotation channels in ``order``.

    ``root_positions`` (n_frames, 3) and offsets are in output units, already in BVH axes;
    ``euler_deg`` (n_frames, n_joints, 3) holds each joint's angles in ``order``.
    ``translations``: joint index -> (n_frames, 3), the joint's offset from its parent on each
    frame (output units, the parent's axes); those joints get three position channels before
    their rotation channels, as the root has (readers take a non-root joint's position channels
    as its offset in that frame). Joints are listed in the hierarchy's depth-first order.
    """
    moving = translations or {}
    for j in joints:
        if not _NAME_OK.match(j.name):
            raise ValueError(f"BVH joint names cannot contain spaces: {j.name!r}")
    rot_names = " ".join(f"{a}rotation" for a in order)
    out: list[str] = ["HIERARCHY"]
    children: dict[int, list[int]] = {}
    for i, j in enumerate(joints):
        children.setdefault(j.parent, []).append(i)
    fmt = f"{{:.{decimals}f}}"

    def vec(v: F64) -> str:
        return " ".join(fmt.format(float(x) + 0.0) for x in v)

    def emit(i: int, depth: int) -> None:
        pad = "\t" * depth
        j = joints[i]
        out.append(f"{pad}{'ROOT' if j.parent < 0 else 'JOINT'} {j.name}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET {vec(j.offset)}")
        if j.parent < 0 or i in moving:
            out.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rot_names}")
        else:
            out.append(f"{pad}\tCHANNELS 3 {rot_names}")
        for c in children.get(i, []):
            emit(c, depth + 1)
        if j.end_site is not None:
            out.append(f"{pad}\tEnd Site")
            out.append(f"{pad}\t{{")
            out.append(f"{pad}\t\tOFFSET {vec(j.end_site)}")
            out.append(f"{pad}\t}}")
        out.append(f"{pad}}}")

    emit(0, 0)
    n_frames = root_positions.shape[0]
    out.append("MOTION")
    out.append(f"Frames: {n_frames}")
    out.append(f"Frame Time: {frame_time_s:.12g}")
    if moving:  # each joint's channels in turn: its positions (if any), then its angles
        values = np.concatenate([root_positions] + [
            block for k in range(len(joints))
            for block in ([moving[k]] if k in moving and k else []) + [euler_deg[:, k]]], axis=1)
    else:
        values = np.concatenate([root_positions, euler_deg.reshape(n_frames, -1)], axis=1)
    values = np.where(np.abs(values) < 0.5 * 10.0 ** (-decimals), 0.0, values)  # no "-0.000000"
    line_fmt = " ".join([fmt] * values.shape[1])
    out.extend(line_fmt.format(*row) for row in values.tolist())
    return "\n".join(out) + "\n"
