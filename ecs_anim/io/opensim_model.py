"""OpenSim models (``.osim``): the joint tree, read with a small XML reader, and its forward
kinematics over a motion's coordinates.

Both file generations are read: OpenSim 4 (a ``JointSet`` whose joints name their parent and
child frames, ``PhysicalOffsetFrame`` s with ``translation`` and ``orientation``) and OpenSim 3
(each ``Body`` holding its ``joint`` with ``parent_body``, ``location_in_parent``,
``orientation_in_parent``, ``location`` and ``orientation``). A joint is a ``CustomJoint``
(a ``SpatialTransform`` of three rotations and three translations, each along its ``axis`` by a
function of its coordinates: ``Constant``, ``LinearFunction``, ``SimmSpline``,
``NaturalCubicSpline``, ``PiecewiseLinearFunction``, ``MultiplierFunction``) or one of the
fixed-axis joints (``PinJoint``, ``WeldJoint``, ``SliderJoint``, ``UniversalJoint``,
``GimbalJoint``, ``BallJoint``, ``FreeJoint``, ``PlanarJoint``).

Conventions (Simbody's function-based mobilizer, as OpenSim builds a ``CustomJoint``): across a
joint the child's frame turns by the three rotations in order, each about its axis in the frame
the previous ones left (``R = R1 R2 R3``), and moves by the translations along their axes in the
parent's offset frame; an offset frame's ``orientation`` is X-Y-Z body-fixed angles (radians).
"""

from __future__ import annotations

import xml.parsers.expat
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, listed, quoted
from ecs_anim.core.files import read_text
from ecs_anim.core.rotations import axis_angle, rot_axis

F64 = NDArray[np.float64]

GROUND = "ground"
#: Axes of the fixed-axis joints: (rotation or translation, axis) per coordinate, in order.
_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
FIXED_AXES: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "PinJoint": (("rotation", _Z),),
    "WeldJoint": (),
    "SliderJoint": (("translation", _X),),
    "UniversalJoint": (("rotation", _X), ("rotation", _Y)),
    "GimbalJoint": (("rotation", _X), ("rotation", _Y), ("rotation", _Z)),
    "BallJoint": (("rotation", _X), ("rotation", _Y), ("rotation", _Z)),
    "FreeJoint": (("rotation", _X), ("rotation", _Y), ("rotation", _Z),
                  ("translation", _X), ("translation", _Y), ("translation", _Z)),
    "PlanarJoint": (("rotation", _Z), ("translation", _X), ("translation", _Y)),
}
FUNCTIONS = ("Constant", "LinearFunction", "SimmSpline", "NaturalCubicSpline",
             "PiecewiseLinearFunction", "MultiplierFunction")


@dataclass
class XmlNode:
    """One XML element: its tag, attributes, text (stripped) and children, and the line it
    starts on (for messages naming the place in the file)."""

    tag: str
    attrib: dict[str, str]
    line: int
    children: list[XmlNode] = field(default_factory=list)
    text: str = ""

    def child(self, tag: str) -> XmlNode | None:
        return next((c for c in self.children if c.tag == tag), None)

    def walk(self) -> Iterator[XmlNode]:
        yield self
        for c in self.children:
            yield from c.walk()

    @property
    def name(self) -> str:
        return self.attrib.get("name", "")


def parse_xml(path: str) -> XmlNode:
    """The file's root element, with line numbers; :class:`InputError` at the line where the
    XML breaks."""
    text = read_text(path)
    stack: list[XmlNode] = [XmlNode("#document", {}, 0)]
    chunks: list[list[str]] = [[]]
    parser = xml.parsers.expat.ParserCreate()

    def start(tag: str, attrib: dict[str, str]) -> None:
        node = XmlNode(tag, attrib, parser.CurrentLineNumber)
        stack[-1].children.append(node)
        stack.append(node)
        chunks.append([])

    def end(_tag: str) -> None:
        stack.pop().text = "".join(chunks.pop()).strip()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = lambda data: chunks[-1].append(data)
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError as exc:
        raise InputError(path, f"not well-formed XML: {xml.parsers.expat.ErrorString(exc.code)}",
                         exc.lineno) from None
    if not stack[0].children:
        raise InputError(path, "no XML element in the file", 1)
    return stack[0].children[0]


@dataclass
class OsimFunction:
    """A function of one coordinate (OpenSim's ``Function`` kinds in :data:`FUNCTIONS`):
    ``kind``, its points ``x`` and ``y`` (a line: slope and intercept; a constant: its value),
    cubic coefficients ``b, c, d`` of a spline, and a ``scale`` (``MultiplierFunction``)."""

    kind: str
    x: F64
    y: F64
    b: F64 | None = None
    c: F64 | None = None
    d: F64 | None = None
    scale: float = 1.0

    def __call__(self, q: F64) -> F64:
        """The function's value at ``q`` (n_frames,)."""
        if self.kind == "Constant":
            out = np.full(q.shape, self.y[0])
        elif self.kind == "LinearFunction":
            out = self.y[0] * q + self.y[1]
        elif self.kind == "PiecewiseLinearFunction" or self.b is None:
            out = np.interp(q, self.x, self.y)
        else:
            assert self.c is not None and self.d is not None
            k = np.clip(np.searchsorted(self.x, q, side="right") - 1, 0, len(self.x) - 1)
            dx = q - self.x[k]
            out = self.y[k] + dx * (self.b[k] + dx * (self.c[k] + dx * self.d[k]))
            # Beyond the points a spline goes on along its end slope (SimmSpline's rule).
            below, above = q < self.x[0], q > self.x[-1]
            out[below] = self.y[0] + (q[below] - self.x[0]) * self.b[0]
            out[above] = self.y[-1] + (q[above] - self.x[-1]) * self.b[-1]
        result: F64 = self.scale * out
        return result


def spline_coefficients(x: F64, y: F64, natural: bool) -> tuple[F64, F64, F64]:
    """Cubic spline coefficients (b, c, d) per point (n,), value ``y[k] + t (b[k] + t (c[k] +
    t d[k]))`` at ``x[k] + t``: natural end conditions, or Forsythe, Malcolm and Moler's (the
    third derivative at each end that of the cubic through the four end points), which
    OpenSim's ``SimmSpline`` uses. Two points make a line; ``x`` increasing."""
    n = len(x)
    h = np.diff(x)
    slope = np.diff(y) / h
    if n == 2:
        return np.full(2, slope[0]), np.zeros(2), np.zeros(2)
    # Second derivatives M (n,) from the tridiagonal system, end rows by the end condition.
    a = np.zeros((n, n))
    rhs = np.zeros(n)
    for k in range(1, n - 1):
        a[k, k - 1:k + 2] = h[k - 1], 2 * (h[k - 1] + h[k]), h[k]
        rhs[k] = 6 * (slope[k] - slope[k - 1])
    if natural or n < 4:
        a[0, 0] = a[-1, -1] = 1.0
    else:
        # M' at each end equals the third derivative of the cubic through its four points.
        third = [6 * _third_difference(x[:4], y[:4]), 6 * _third_difference(x[-4:], y[-4:])]
        a[0, :2], rhs[0] = (-1.0, 1.0), third[0] * h[0]
        a[-1, -2:], rhs[-1] = (-1.0, 1.0), third[1] * h[-1]
    m = np.linalg.solve(a, rhs)
    b = np.empty(n)
    b[:-1] = slope - h * (2 * m[:-1] + m[1:]) / 6
    b[-1] = slope[-1] + h[-1] * (m[-2] + 2 * m[-1]) / 6
    c = m / 2
    d = np.zeros(n)
    d[:-1] = np.diff(m) / (6 * h)
    return b, c, d


def _third_difference(x: F64, y: F64) -> float:
    """The third divided difference of four points (a cubic's leading coefficient)."""
    d1 = np.diff(y) / np.diff(x)
    d2 = np.diff(d1) / (x[2:] - x[:-2])
    return float((d2[1] - d2[0]) / (x[3] - x[0]))


@dataclass
class TransformAxis:
    """One motion of a joint: a ``rotation`` (radians) or ``translation`` (m) along ``axis``
    (3,) by ``function`` of ``coordinate`` (None: a constant)."""

    kind: str
    axis: F64
    coordinate: str | None
    function: OsimFunction


@dataclass
class OsimJoint:
    """A joint: parent and child bodies, their offset frames (rotation (3, 3), translation
    (3,) in the body), its coordinates and motions, and where it is in the file."""

    name: str
    kind: str
    line: int
    parent: str
    child: str
    parent_offset: tuple[F64, F64]
    child_offset: tuple[F64, F64]
    coordinates: list[str]
    axes: list[TransformAxis]


@dataclass
class OsimModel:
    """A model's joints from the ground outwards (a parent's joint before its children's), and
    each coordinate's default value and whether it is a rotation (given in degrees in a
    ``.mot`` with ``inDegrees=yes``)."""

    path: str
    name: str
    joints: list[OsimJoint]
    defaults: dict[str, float]
    rotational: dict[str, bool]


def read_osim(path: str | Path) -> OsimModel:
    """Read an OpenSim model's joint tree. Raises :class:`InputError` naming the file and line:
    broken XML, no joint, a joint of an unknown kind, a missing or malformed frame, axis or
    function, a coordinate no joint declares, a body with two parents, or a tree not rooted on
    the ground."""
    path = str(path)
    root = parse_xml(path)
    model = root.child("Model") if root.tag == "OpenSimDocument" else root
    if model is None or model.tag != "Model":
        raise InputError(path, f"expected an OpenSim model (<OpenSimDocument><Model>), found "
                               f"<{root.tag}>", root.line)
    if any(n.tag == "JointSet" for n in model.walk()):
        # Offset frames a body declares (its components): their socket_parent ".." is the body.
        offsets = {f.name: (f, body.name or GROUND) for body in model.walk()
                   if body.tag in ("Body", "Ground") for f in body.walk()
                   if f.tag == "PhysicalOffsetFrame"}
        joints = [_joint_v4(path, n, offsets) for n in _joint_elements(model, "JointSet")]
    else:
        joints = [_joint_v3(path, n, body) for body in model.walk() if body.tag == "Body"
                  for n in _joint_elements(body, "joint")]
    if not joints:
        raise InputError(path, "the model has no joint (no JointSet, no Body with a joint)",
                         model.line)
    defaults: dict[str, float] = {}
    stated: dict[str, bool] = {}
    for node in model.walk():
        if node.tag == "Coordinate" and node.name:
            defaults[node.name] = _number(path, node.child("default_value"), 0.0)
            motion = node.child("motion_type")
            if motion is not None:
                stated[node.name] = motion.text.lower() != "translational"
    for joint in joints:
        for axis in joint.axes:
            if axis.coordinate is not None and axis.coordinate not in defaults:
                raise InputError(path, f"joint {quoted(joint.name)}: its {axis.kind} axis uses "
                                       f"coordinate {quoted(axis.coordinate)}, which no joint "
                                       "declares", joint.line)
    # Without a stated motion_type (OpenSim 4 infers it), a coordinate is a rotation unless it
    # drives translations only.
    turning = {a.coordinate for j in joints for a in j.axes if a.kind == "rotation"}
    moving = {a.coordinate for j in joints for a in j.axes if a.kind == "translation"}
    rotational = {name: stated.get(name, name in turning or name not in moving)
                  for name in defaults}
    return OsimModel(path, model.name, _from_ground(path, joints), defaults, rotational)


def _joint_elements(parent: XmlNode, holder: str) -> list[XmlNode]:
    """The joint elements under ``parent``'s ``holder`` element(s) (``JointSet``: its objects;
    a v3 ``Body``'s ``joint``: the one joint in it)."""
    out = []
    for node in parent.children if holder == "joint" else parent.walk():
        if node.tag != holder:
            continue
        objects = node.child("objects") if holder == "JointSet" else node
        out += [j for j in (objects.children if objects else []) if j.tag.endswith("Joint")]
    return out


def _joint_v4(path: str, node: XmlNode, offsets: dict[str, tuple[XmlNode, str]]) -> OsimJoint:
    """An OpenSim 4 joint: its frames named by ``socket_parent_frame``/``socket_child_frame``
    (one of its ``frames``, else an offset frame a body declares, ``offsets``: name -> (frame,
    the body), else a body's path)."""
    own = {f.name: (f, node.name) for f in (node.child("frames") or XmlNode("", {}, 0)).children}
    frames = {**offsets, **own}

    def side(socket: str) -> tuple[str, tuple[F64, F64]]:
        ref = node.child(socket)
        if ref is None or not ref.text:
            raise InputError(path, f"joint {quoted(node.name)}: no <{socket}>", node.line)
        found = frames.get(ref.text.split("/")[-1])
        if found is None:
            return ref.text.split("/")[-1], (np.eye(3), np.zeros(3))
        frame, owner = found
        body = frame.child("socket_parent")
        if body is None or not body.text:
            raise InputError(path, f"frame {quoted(frame.name)}: no <socket_parent>", frame.line)
        name = body.text.rstrip("/").split("/")[-1]
        return owner if name == ".." else name, _offset(path, frame, "translation", "orientation")

    parent, parent_offset = side("socket_parent_frame")
    child, child_offset = side("socket_child_frame")
    coords = [c.name for c in (node.child("coordinates") or XmlNode("", {}, 0)).children
              if c.tag == "Coordinate"]
    return OsimJoint(node.name, node.tag, node.line, parent, child, parent_offset,
                     child_offset, coords, _axes(path, node, coords))


def _joint_v3(path: str, node: XmlNode, body: XmlNode) -> OsimJoint:
    """An OpenSim 3 joint, inside its child ``body``."""
    parent = node.child("parent_body")
    if parent is None or not parent.text:
        raise InputError(path, f"joint {quoted(node.name)}: no <parent_body>", node.line)
    coord_set = node.child("CoordinateSet")
    objects = coord_set.child("objects") if coord_set else None
    coords = [c.name for c in (objects.children if objects else []) if c.tag == "Coordinate"]
    return OsimJoint(node.name, node.tag, node.line, parent.text, body.name,
                     _offset(path, node, "location_in_parent", "orientation_in_parent"),
                     _offset(path, node, "location", "orientation"), coords,
                     _axes(path, node, coords))


def _offset(path: str, node: XmlNode, translation: str, orientation: str) -> tuple[F64, F64]:
    """An offset frame: (rotation (3, 3) from X-Y-Z body-fixed angles, translation (3,))."""
    angles = _vector(path, node, orientation, 3, np.zeros(3))
    return (rot_axis(0, angles[0]) @ rot_axis(1, angles[1]) @ rot_axis(2, angles[2]),
            _vector(path, node, translation, 3, np.zeros(3)))


def _vector(path: str, node: XmlNode, tag: str, size: int, default: F64 | None = None) -> F64:
    """The numbers in ``node``'s child ``tag`` ((size,)), or ``default`` where it has none."""
    item = node.child(tag)
    if item is None and default is not None:
        return default
    where = item.line if item is not None else node.line
    try:
        values = np.array([float(v) for v in (item.text if item is not None else "").split()])
    except ValueError:
        values = np.array([])
    if len(values) != size or not np.all(np.isfinite(values)):
        raise InputError(path, f"<{node.tag} name={quoted(node.name)}>: expected {size} "
                               f"number(s) in <{tag}>, found "
                               f"{quoted(item.text if item is not None else '(nothing)', 40)}",
                         where)
    return values


def _number(path: str, node: XmlNode | None, default: float) -> float:
    if node is None:
        return default
    try:
        return float(node.text)
    except ValueError:
        raise InputError(path, f"<{node.tag}>: expected a number, found {quoted(node.text, 40)}",
                         node.line) from None


def _axes(path: str, node: XmlNode, coords: list[str]) -> list[TransformAxis]:
    """A joint's motions: a ``CustomJoint``'s ``SpatialTransform`` (rotation1-3 then
    translation1-3), or a fixed-axis joint's (:data:`FIXED_AXES`) by its coordinates."""
    if node.tag != "CustomJoint":
        fixed = FIXED_AXES.get(node.tag)
        if fixed is None:
            raise InputError(path, f"joint {quoted(node.name)}: a {node.tag}, which import does "
                                   f"not read (it reads CustomJoint, {listed(list(FIXED_AXES), 8)})",
                             node.line)
        if len(coords) != len(fixed):
            raise InputError(path, f"joint {quoted(node.name)}: a {node.tag} has {len(fixed)} "
                                   f"coordinate(s), found {len(coords)}", node.line)
        identity = OsimFunction("LinearFunction", np.zeros(0), np.array([1.0, 0.0]))
        return [TransformAxis(kind, np.array(axis), coord, identity)
                for (kind, axis), coord in zip(fixed, coords, strict=True)]
    transform = node.child("SpatialTransform")
    if transform is None:
        raise InputError(path, f"joint {quoted(node.name)}: a CustomJoint with no "
                               "<SpatialTransform>", node.line)
    out = []
    for item in transform.children:
        if item.tag != "TransformAxis":
            continue
        kind = "rotation" if item.name.startswith("rotation") else "translation"
        axis = _vector(path, item, "axis", 3)
        if np.linalg.norm(axis) < 1e-12:
            raise InputError(path, f"joint {quoted(node.name)}, {item.name}: a zero axis",
                             item.line)
        names = (item.child("coordinates") or XmlNode("", {}, 0)).text.split()
        if len(names) > 1:
            raise InputError(path, f"joint {quoted(node.name)}, {item.name}: a function of "
                                   f"{len(names)} coordinates, which import does not read",
                             item.line)
        out.append(TransformAxis(kind, axis / np.linalg.norm(axis), names[0] if names else None,
                                 _function(path, node, item)))
    order = {f"{k}{i}": n for n, (k, i) in enumerate(
        (k, i) for k in ("rotation", "translation") for i in (1, 2, 3))}
    names = [i.name for i in transform.children if i.tag == "TransformAxis"]
    return [a for _, a in sorted(zip((order.get(n, 9) for n in names), out, strict=True),
                                 key=lambda pair: pair[0])]


def _function(path: str, joint: XmlNode, item: XmlNode) -> OsimFunction:
    """A transform axis's function: the element of a kind in :data:`FUNCTIONS` in it (OpenSim
    4) or in its ``<function>`` (OpenSim 3); none: the identity."""
    holder = item.child("function") or item
    node = next((c for c in holder.children if c.tag in FUNCTIONS), None)
    unknown = next((c for c in holder.children if c.tag not in FUNCTIONS and
                    c.tag not in ("coordinates", "axis", "function")), None)
    if node is None:
        if unknown is not None:
            raise InputError(path, f"joint {quoted(joint.name)}, {item.name}: a function "
                                   f"<{unknown.tag}>, which import does not read (it reads "
                                   f"{listed(list(FUNCTIONS), 6)})", unknown.line)
        return OsimFunction("LinearFunction", np.zeros(0), np.array([1.0, 0.0]))
    return _function_of(path, joint, item, node)


def _function_of(path: str, joint: XmlNode, item: XmlNode, node: XmlNode) -> OsimFunction:
    where = f"joint {quoted(joint.name)}, {item.name}"
    if node.tag == "MultiplierFunction":
        inner = node.child("function")
        inner_node = next((c for c in (inner.children if inner else []) if c.tag in FUNCTIONS),
                          None)
        if inner_node is None:
            raise InputError(path, f"{where}: a MultiplierFunction with no function", node.line)
        function = _function_of(path, joint, item, inner_node)
        function.scale *= _number(path, node.child("scale"), 1.0)
        return function
    if node.tag == "Constant":
        return OsimFunction("Constant", np.zeros(0), np.array([_number(path, node.child("value"), 0.0)]))
    if node.tag == "LinearFunction":
        return OsimFunction("LinearFunction", np.zeros(0), _vector(path, node, "coefficients", 2))
    x_node, y_node = node.child("x"), node.child("y")
    try:
        x = np.array([float(v) for v in (x_node.text if x_node else "").split()])
        y = np.array([float(v) for v in (y_node.text if y_node else "").split()])
    except ValueError:
        x = y = np.zeros(0)
    if len(x) < 2 or len(x) != len(y) or not np.all(np.diff(x) > 0) or \
            not np.all(np.isfinite(y)):
        raise InputError(path, f"{where}: a {node.tag} needs two or more points with x "
                               f"increasing and as many y (found {len(x)} x, {len(y)} y)",
                         node.line)
    if node.tag == "PiecewiseLinearFunction":
        return OsimFunction(node.tag, x, y)
    b, c, d = spline_coefficients(x, y, natural=node.tag == "NaturalCubicSpline")
    return OsimFunction(node.tag, x, y, b, c, d)


def _from_ground(path: str, joints: list[OsimJoint]) -> list[OsimJoint]:
    """The joints ordered from the ground outwards; :class:`InputError` for a body with two
    parent joints or joints that do not reach the ground."""
    by_child: dict[str, OsimJoint] = {}
    for joint in joints:
        if joint.child in by_child:
            raise InputError(path, f"body {quoted(joint.child)} is the child of two joints "
                                   f"({by_child[joint.child].name}, {joint.name}): a closed "
                                   "loop, which import does not read", joint.line)
        by_child[joint.child] = joint
    ordered: list[OsimJoint] = []
    placed = {GROUND}
    while len(ordered) < len(joints):
        ready = [j for j in joints if j.parent in placed and j.child not in placed]
        if not ready:
            lost = next(j for j in joints if j.child not in placed)
            raise InputError(path, f"joint {quoted(lost.name)}: its parent "
                                   f"{quoted(lost.parent)} is not connected to the ground",
                             lost.line)
        ordered += ready
        placed |= {j.child for j in ready}
    return ordered


def joint_transforms(joint: OsimJoint, values: Callable[[str], F64], n_frames: int
                     ) -> tuple[F64, F64]:
    """The child's frame in the parent's across ``joint`` at each frame: rotations
    (n_frames, 3, 3) and translations (n_frames, 3), body to body (offset frames included).
    ``values(name)``: the coordinate's values (n_frames,), radians or metres."""
    rotation = np.tile(joint.parent_offset[0], (n_frames, 1, 1))
    translation = np.tile(joint.parent_offset[1], (n_frames, 1))
    moved = np.zeros((n_frames, 3))
    turn = np.tile(np.eye(3), (n_frames, 1, 1))
    for axis in joint.axes:
        q = values(axis.coordinate) if axis.coordinate is not None else np.zeros(n_frames)
        amount = axis.function(q)
        if axis.kind == "translation":
            moved += amount[:, None] * axis.axis
        else:
            turn = turn @ axis_angle(np.broadcast_to(axis.axis, (n_frames, 3)), amount)
    # parent -> joint frame F (offset), F -> M (the motion: translate in F, then turn),
    # M -> child (the inverse of the child's offset).
    translation = translation + np.einsum("fij,fj->fi", rotation, moved)
    rotation = rotation @ turn
    child_r, child_p = joint.child_offset
    translation = translation - np.einsum("fij,j->fi", rotation @ child_r.T, child_p)
    rotation = rotation @ child_r.T
    return rotation, translation


def body_frames(model: OsimModel, values: Callable[[str], F64], n_frames: int
                ) -> dict[str, tuple[F64, F64, F64]]:
    """Every body's frame in the ground at each frame, and its joint's centre: name ->
    (rotation (n_frames, 3, 3), origin (n_frames, 3), joint centre (n_frames, 3)), metres, the
    model's axes (Y up). A loop over the joints, vectorized over frames."""
    out: dict[str, tuple[F64, F64, F64]] = {
        GROUND: (np.tile(np.eye(3), (n_frames, 1, 1)), np.zeros((n_frames, 3)),
                 np.zeros((n_frames, 3)))}
    for joint in model.joints:
        parent_r, parent_p, _ = out[joint.parent]
        local_r, local_p = joint_transforms(joint, values, n_frames)
        rotation = parent_r @ local_r
        origin = parent_p + np.einsum("fij,fj->fi", parent_r, local_p)
        centre = origin + np.einsum("fij,j->fi", rotation, joint.child_offset[1])
        out[joint.child] = (rotation, origin, centre)
    return out


__all__ = ["OsimFunction", "OsimJoint", "OsimModel", "TransformAxis", "body_frames",
           "joint_transforms", "parse_xml", "read_osim", "spline_coefficients"]
