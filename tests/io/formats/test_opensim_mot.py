"""OpenSim joint angles (.mot) on their model (.osim): a gait2392-like model (pelvis, hips of
3 dof, knees whose translation follows the knee angle by splines, ankles, subtalar and mtp
joints on oblique axes, a lumbar of 3 dof, a patella welded to the femur) written by the test in
OpenSim 4 and OpenSim 3 form, with a .mot of a known motion, imports to joints within 1 mm of
the test's own forward kinematics on every frame. Without a model a .mot is refused in one line
saying what is missing; a malformed .mot or .osim in one line naming the file and line."""

from __future__ import annotations

import numpy as np
import pytest

from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import InputError
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.export import play_on
from ecs_anim.io.importing import UP_AXES
from ecs_anim.io.opensim_model import read_osim, spline_coefficients
from ecs_anim.io.opensim_mot import import_mot, read_mot

HEADER = ("Coordinates\nversion=1\nnRows=2\nnColumns=4\ninDegrees=yes\n\n"
          "Units are S.I. units (second, meters, Newtons, ...)\nendheader\n")
LABELS = "time\tpelvis_tilt\thip_flexion_r\tknee_angle_r\n"
ROWS = "0.00\t1.5\t20.0\t-5.0\n0.01\t1.6\t21.0\t-6.0\n"

# gait2392's knee translation splines (x, y of the tibia in the femur against the knee angle).
KNEE_X = ([-2.0944, -1.74533, -1.39626, -1.0472, -0.698132, -0.349066, -0.174533, 0.197344,
           0.337395, 0.490178, 1.52146, 2.0944],
          [-0.0032, 0.00179, 0.00411, 0.0041, 0.00212, -0.001, -0.0031, -0.005227, -0.005435,
           -0.005574, -0.005435, -0.00525])
KNEE_Y = ([-2.0944, -1.22173, -0.523599, -0.349066, -0.174533, 0.159149, 2.0944],
          [-0.4226, -0.4082, -0.399, -0.3976, -0.3966, -0.395264, -0.396])
Z, X, Y = (0, 0, 1), (1, 0, 0), (0, 1, 0)


def joints(side: str) -> list[dict]:
    """One leg's joints: name, kind, parent, child, parent offset (translation, orientation),
    child offset, motions (rotation/translation, axis, coordinate or None, function)."""
    m = 1.0 if side == "r" else -1.0  # the left mirrors z; axes (pseudo-vectors) mirror x, y

    def axis(a):
        return (a[0], a[1], a[2]) if side == "r" else (-a[0], -a[1], a[2])

    s = side
    return [
        dict(name=f"hip_{s}", kind="CustomJoint", parent="pelvis", child=f"femur_{s}",
             p_off=((-0.0707, -0.0661, 0.0835 * m), (0, 0, 0)), c_off=((0, 0, 0), (0, 0, 0)),
             axes=[("rotation", Z, f"hip_flexion_{s}", None),
                   ("rotation", axis(X), f"hip_adduction_{s}", None),
                   ("rotation", axis(Y), f"hip_rotation_{s}", None)]),
        dict(name=f"patellofemoral_{s}", kind="WeldJoint", parent=f"femur_{s}",
             child=f"patella_{s}", p_off=((0.05, -0.40, 0.0), (0, 0, 0.1)),
             c_off=((0, 0, 0), (0, 0, 0)), axes=[]),
        dict(name=f"knee_{s}", kind="CustomJoint", parent=f"femur_{s}", child=f"tibia_{s}",
             p_off=((0, 0, 0), (0, 0, 0)), c_off=((0, 0, 0), (0, 0, 0)),
             axes=[("rotation", Z, f"knee_angle_{s}", None),
                   ("translation", X, f"knee_angle_{s}", ("SimmSpline", KNEE_X)),
                   ("translation", Y, f"knee_angle_{s}", ("SimmSpline", KNEE_Y))]),
        dict(name=f"ankle_{s}", kind="PinJoint", parent=f"tibia_{s}", child=f"talus_{s}",
             p_off=((0, -0.43, 0), (0.175895 * m, -0.105208 * m, 0.0186622)),
             c_off=((0, 0, 0), (0.175895 * m, -0.105208 * m, 0.0186622)),
             axes=[("rotation", Z, f"ankle_angle_{s}", None)]),
        dict(name=f"subtalar_{s}", kind="CustomJoint", parent=f"talus_{s}", child=f"calcn_{s}",
             p_off=((-0.04877, -0.04195, 0.00792 * m), (0, 0, 0)), c_off=((0, 0, 0), (0, 0, 0)),
             axes=[("rotation", axis((0.78717961, 0.60474746, -0.12094949)),
                    f"subtalar_angle_{s}", None)]),
        dict(name=f"mtp_{s}", kind="PinJoint", parent=f"calcn_{s}", child=f"toes_{s}",
             p_off=((0.1788, -0.002, 0.00108 * m), (-1.76819 * m, 0.906223 * m, 1.76819)),
             c_off=((0, 0, 0), (-1.76819 * m, 0.906223 * m, 1.76819)),
             axes=[("rotation", Z, f"mtp_angle_{s}", None)]),
    ]


MODEL = [
    dict(name="ground_pelvis", kind="CustomJoint", parent="ground", child="pelvis",
         p_off=((0, 0, 0), (0, 0, 0)), c_off=((0, 0, 0), (0, 0, 0)),
         axes=[("rotation", Z, "pelvis_tilt", None), ("rotation", X, "pelvis_list", None),
               ("rotation", Y, "pelvis_rotation", None), ("translation", X, "pelvis_tx", None),
               ("translation", Y, "pelvis_ty", None), ("translation", Z, "pelvis_tz", None)]),
    *joints("r"), *joints("l"),
    dict(name="back", kind="CustomJoint", parent="pelvis", child="torso",
         p_off=((-0.1007, 0.0815, 0), (0, 0, 0)), c_off=((0, 0, 0), (0, 0, 0)),
         axes=[("rotation", Z, "lumbar_extension", None), ("rotation", X, "lumbar_bending", None),
               ("rotation", Y, "lumbar_rotation", None)]),
    # Rajagopal's arms hang from the torso lower than the pelvis's origin: still the trunk.
    *(dict(name=f"{name}_r", kind="WeldJoint", parent=parent, child=f"{child}_r",
           p_off=(offset, (0, 0, 0)), c_off=((0, 0, 0), (0, 0, 0)), axes=[])
      for name, parent, child, offset in (
          ("acromial", "torso", "humerus", (0.003, 0.372, 0.17)),
          ("elbow", "humerus_r", "ulna", (0.013, -0.286, -0.0096)),
          ("radius_lunate", "ulna_r", "hand", (-0.0087, -0.231, 0.0235)))),
]
TRANSLATIONAL = {"pelvis_tx", "pelvis_ty", "pelvis_tz"}


def coordinates(joint):
    return list(dict.fromkeys(c for _, _, c, _ in joint["axes"] if c))


def text(v):
    return " ".join(repr(float(x)) for x in v)


def function_xml(function, v4: bool) -> str:
    if function is None:
        inner = "<LinearFunction name=\"function\"><coefficients>1 0</coefficients></LinearFunction>"
    else:
        kind, (x, y) = function
        inner = f"<{kind} name=\"function\"><x>{text(x)}</x><y>{text(y)}</y></{kind}>"
    if v4:
        return inner
    return "<function>" + inner.replace(' name="function"', "") + "</function>"


def coordinate_xml(name: str) -> str:
    kind = "translational" if name in TRANSLATIONAL else "rotational"
    return (f"<Coordinate name=\"{name}\"><motion_type>{kind}</motion_type>"
            f"<default_value>0</default_value></Coordinate>")


def transform_xml(joint, v4: bool) -> str:
    if joint["kind"] != "CustomJoint":
        return ""
    rows = []
    count = {"rotation": 0, "translation": 0}
    for kind, axis, coordinate, function in joint["axes"]:
        count[kind] += 1
        rows.append(f"<TransformAxis name=\"{kind}{count[kind]}\"><coordinates>{coordinate}"
                    f"</coordinates><axis>{text(axis)}</axis>{function_xml(function, v4)}"
                    "</TransformAxis>")
    return "<SpatialTransform>" + "".join(rows) + "</SpatialTransform>"


def osim_v4(model=MODEL) -> str:
    bodies = sorted({j["child"] for j in model})
    out = ["<?xml version=\"1.0\" encoding=\"UTF-8\" ?>", "<OpenSimDocument Version=\"40000\">",
           "<Model name=\"gait_test\">", "<BodySet name=\"bodyset\"><objects>"]
    out += [f"<Body name=\"{b}\"><mass>1</mass></Body>" for b in bodies]
    out += ["</objects></BodySet>", "<JointSet name=\"jointset\"><objects>"]
    for j in model:
        parent = "/ground" if j["parent"] == "ground" else f"/bodyset/{j['parent']}"
        coords = "".join(coordinate_xml(c) for c in coordinates(j))
        out.append(
            f"<{j['kind']} name=\"{j['name']}\">"
            f"<socket_parent_frame>{j['parent']}_offset</socket_parent_frame>"
            f"<socket_child_frame>{j['child']}_offset</socket_child_frame>"
            f"<coordinates>{coords}</coordinates><frames>"
            f"<PhysicalOffsetFrame name=\"{j['parent']}_offset\"><socket_parent>{parent}"
            f"</socket_parent><translation>{text(j['p_off'][0])}</translation>"
            f"<orientation>{text(j['p_off'][1])}</orientation></PhysicalOffsetFrame>"
            f"<PhysicalOffsetFrame name=\"{j['child']}_offset\"><socket_parent>/bodyset/"
            f"{j['child']}</socket_parent><translation>{text(j['c_off'][0])}</translation>"
            f"<orientation>{text(j['c_off'][1])}</orientation></PhysicalOffsetFrame></frames>"
            f"{transform_xml(j, True)}</{j['kind']}>")
    out += ["</objects></JointSet>", "</Model>", "</OpenSimDocument>"]
    return "\n".join(out)


def osim_v3(model=MODEL) -> str:
    out = ["<?xml version=\"1.0\" encoding=\"UTF-8\" ?>", "<OpenSimDocument Version=\"30000\">",
           "<Model name=\"gait_test\">", "<BodySet><objects>", "<Body name=\"ground\"><joint/></Body>"]
    for j in model:
        coords = "".join(coordinate_xml(c) for c in coordinates(j))
        out.append(
            f"<Body name=\"{j['child']}\"><mass>1</mass><joint><{j['kind']} name=\"{j['name']}\">"
            f"<parent_body>{j['parent']}</parent_body>"
            f"<location_in_parent>{text(j['p_off'][0])}</location_in_parent>"
            f"<orientation_in_parent>{text(j['p_off'][1])}</orientation_in_parent>"
            f"<location>{text(j['c_off'][0])}</location>"
            f"<orientation>{text(j['c_off'][1])}</orientation>"
            f"<CoordinateSet><objects>{coords}</objects></CoordinateSet>"
            f"{transform_xml(j, False)}</{j['kind']}></joint></Body>")
    out += ["</objects></BodySet>", "</Model>", "</OpenSimDocument>"]
    return "\n".join(out)


FPS = 100.0
N_FRAMES = 240


def known_motion() -> dict[str, np.ndarray]:
    """A walk's coordinates (radians, metres) at 1 m/s, 1 stride a second."""
    t = np.arange(N_FRAMES) / FPS
    phase = 2 * np.pi * t
    q = {"pelvis_tx": 1.0 * t, "pelvis_ty": 0.93 + 0.02 * np.cos(2 * phase),
         "pelvis_tz": 0.01 * np.sin(phase), "pelvis_tilt": np.radians(-5 + 2 * np.sin(2 * phase)),
         "pelvis_list": np.radians(3 * np.sin(phase)),
         "pelvis_rotation": np.radians(5 * np.sin(phase) + 20),
         "lumbar_extension": np.radians(-4 + 2 * np.sin(2 * phase)),
         "lumbar_bending": np.radians(-2 * np.sin(phase)),
         "lumbar_rotation": np.radians(-4 * np.sin(phase))}
    for s, shift in (("r", 0.0), ("l", np.pi)):
        p = phase + shift
        q |= {f"hip_flexion_{s}": np.radians(10 + 25 * np.sin(p)),
              f"hip_adduction_{s}": np.radians(3 * np.cos(p)),
              f"hip_rotation_{s}": np.radians(5 * np.sin(p)),
              f"knee_angle_{s}": np.radians(-30 - 30 * np.sin(p - 1.2)),
              f"ankle_angle_{s}": np.radians(12 * np.sin(p + 0.5)),
              f"subtalar_angle_{s}": np.radians(6 * np.sin(p)),
              f"mtp_angle_{s}": np.radians(15 + 15 * np.sin(p + 2))}
    return q


def write_mot(path, q: dict[str, np.ndarray], labels=None) -> None:
    names = labels or list(q)
    t = np.arange(N_FRAMES) / FPS
    rows = ["\t".join(f"{v:.10f}" for v in [t[k]] + [
        q[n][k] if n in TRANSLATIONAL else np.degrees(q[n][k]) for n in q]) for k in range(N_FRAMES)]
    path.write_text(f"Coordinates\nversion=1\nnRows={N_FRAMES}\nnColumns={len(q) + 1}\n"
                    "inDegrees=yes\nendheader\n" + "\t".join(["time", *names]) + "\n"
                    + "\n".join(rows) + "\n")


def rotation(axis, angle):
    """Rodrigues, one frame at a time (the test's own forward kinematics)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def euler_xyz(angles):
    return rotation(X, angles[0]) @ rotation(Y, angles[1]) @ rotation(Z, angles[2])


def homogeneous(r, p):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = r, p
    return out


def spline(knots, u):
    x, y = (np.asarray(v, float) for v in knots)
    b, c, d = spline_coefficients(x, y, natural=False)
    k = int(np.clip(np.searchsorted(x, u, side="right") - 1, 0, len(x) - 1))
    return y[k] + (u - x[k]) * (b[k] + (u - x[k]) * (c[k] + (u - x[k]) * d[k]))


def joint_centres(q: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each body's joint centre (n_frames, 3), OpenSim's axes, frame by frame with 4 x 4
    matrices: parent * offset * (translate in F, then rotate R1 R2 R3) * inverse child offset."""
    out = {b: np.zeros((N_FRAMES, 3)) for b in (j["child"] for j in MODEL)}
    for f in range(N_FRAMES):
        world = {"ground": np.eye(4)}
        for j in MODEL:
            turn, move = np.eye(3), np.zeros(3)
            for kind, axis, coordinate, function in j["axes"]:
                value = q[coordinate][f] if coordinate else 0.0
                if function is not None:
                    value = spline(function[1], value)
                if kind == "rotation":
                    turn = turn @ rotation(axis, value)
                else:
                    move = move + value * np.asarray(axis, float)
            offset = homogeneous(euler_xyz(j["p_off"][1]), j["p_off"][0])
            child = homogeneous(euler_xyz(j["c_off"][1]), j["c_off"][0])
            joint_frame = world[j["parent"]] @ offset @ homogeneous(turn, move)
            world[j["child"]] = joint_frame @ np.linalg.inv(child)
            out[j["child"]][f] = joint_frame[:3, 3]
    return out


@pytest.mark.parametrize("version", ["v4", "v3"])
def test_a_mot_on_its_osim_places_the_joints_within_a_millimetre(tmp_path, version):
    q = known_motion()
    osim, mot = tmp_path / "gait_test.osim", tmp_path / "walk.mot"
    osim.write_text(osim_v4() if version == "v4" else osim_v3())
    write_mot(mot, q)
    motion = import_mot(mot, osim)
    assert motion.fps == FPS and len(motion.poses.root_position) == N_FRAMES
    pose = play_on(motion, motion.source_morphology, True).positions
    expected = {name: centre @ UP_AXES["y"].T for name, centre in joint_centres(q).items()}
    errors = {}
    for s in "lr":
        for joint, body in (("hip", "femur"), ("knee", "tibia"), ("ankle", "talus"),
                            ("toe", "toes")):
            errors[f"{joint}_{s}"] = np.linalg.norm(pose[:, J[f"{joint}_{s}"]]
                                                    - expected[f"{body}_{s}"], axis=-1).max()
    errors["spine_1"] = np.linalg.norm(pose[:, J["spine_1"]] - expected["torso"], axis=-1).max()
    assert max(errors.values()) < 0.001, errors
    info = motion.info["opensim"]
    assert info["legs"]["r"] == ["femur_r", "tibia_r", "talus_r", "calcn_r", "toes_r"]
    assert info["trunk"] == ["torso", "humerus_r", "ulna_r", "hand_r"]
    assert info["coordinates_at_default"] == []


def test_the_cli_imports_a_mot_with_its_model_and_refuses_one_without(tmp_path, capsys):
    osim, mot = tmp_path / "gait_test.osim", tmp_path / "walk.mot"
    osim.write_text(osim_v4())
    write_mot(mot, known_motion())
    assert main(["import", str(mot), "--body-model", str(osim), "-o", str(tmp_path / "a")]) == 0
    assert (tmp_path / "a" / "walk.nmo").exists()
    capsys.readouterr()
    assert main(["import", str(mot), "--body-model", str(osim), "--up", "z", "-o",
                 str(tmp_path / "c")]) == 1
    assert "--up does not apply to OpenSim joint angles" in capsys.readouterr().err
    assert main(["import", str(mot), "-o", str(tmp_path / "b")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith(f"error: {mot}: OpenSim joint angles (23 coordinates: pelvis_tx, "
                             "pelvis_ty, pelvis_tz (+20 more); 240 frames) need the model")
    assert err[0].endswith("need the model they were computed on: give --body-model MODEL.osim, "
                           "or import the trial's markers (.trc)")


def test_state_paths_and_missing_columns(tmp_path):
    """OpenSim 4 state labels (/jointset/hip_r/hip_flexion_r/value) name their coordinate; a
    coordinate the file lacks stays at the model's default and is said."""
    q = known_motion()
    del q["lumbar_rotation"]
    osim, mot = tmp_path / "gait_test.osim", tmp_path / "walk.sto"
    osim.write_text(osim_v4())
    write_mot(mot, q, [f"/jointset/x/{n}/value" for n in q])
    motion = import_mot(mot, osim)
    assert motion.info["opensim"]["coordinates_at_default"] == ["lumbar_rotation"]


@pytest.mark.parametrize(("text", "expected"), [
    (LABELS + ROWS, r"bad\.mot:3: no 'endheader'"),
    (HEADER + "pelvis_tilt\n" + ROWS, r"bad\.mot:9: expected a line of column labels"),
    (HEADER + LABELS, r"bad\.mot:9: the file holds no frame"),
    (HEADER + LABELS + "0.00\t1.5\t20.0\n", r"bad\.mot:10: a row of 3 values where the labels"),
    (HEADER + LABELS + "0.00\t1.5\tx\t-5\n", r"bad\.mot:10: expected a number, found 'x'"),
    (HEADER + LABELS + "0\tnan\tnan\tnan\n0.01\tnan\tnan\tnan\n",
     r"bad\.mot: no finite value in any frame for pelvis_tilt, hip_flexion_r, knee_angle_r"),
])
def test_a_malformed_mot_is_refused_naming_file_and_line(text, expected, tmp_path):
    path = tmp_path / "bad.mot"
    path.write_text(text)
    with pytest.raises(InputError, match=expected):
        read_mot(path)


def test_a_mot_of_another_model_or_uneven_times_is_refused(tmp_path):
    osim = tmp_path / "gait_test.osim"
    osim.write_text(osim_v4())
    other = tmp_path / "other.mot"
    other.write_text(HEADER + "time\telbow_flex\n0\t1\n0.01\t2\n")
    with pytest.raises(InputError, match=r"other\.mot: none of the columns \(elbow_flex\) is a "
                                         r"coordinate of the model"):
        import_mot(other, osim)
    uneven = tmp_path / "uneven.mot"
    uneven.write_text(HEADER + LABELS + "0\t1\t2\t3\n0.01\t1\t2\t3\n0.02\t1\t2\t3\n0.05\t1\t2\t3\n")
    with pytest.raises(InputError, match=r"uneven\.mot: time 0\.05 s at frame 4: the times must "
                                         r"increase in even steps"):
        import_mot(uneven, osim)


def broken(model_text: str, old: str, new: str) -> str:
    assert old in model_text
    return model_text.replace(old, new, 1)


@pytest.mark.parametrize(("make", "expected"), [
    (lambda: osim_v4()[:-40], r"bad\.osim:\d+: not well-formed XML"),
    (lambda: "<Model name=\"x\"></Model>", r"bad\.osim:1: the model has no joint"),
    (lambda: "<Skeleton/>", r"bad\.osim:1: expected an OpenSim model"),
    (lambda: broken(osim_v4(), "<PinJoint name=\"ankle_r\"", "<EllipsoidJoint name=\"ankle_r\"")
     .replace("</PinJoint>", "</EllipsoidJoint>", 1),
     r"bad\.osim:\d+: joint 'ankle_r': a EllipsoidJoint, which import does not read"),
    (lambda: broken(osim_v4(), "<axis>0.0 0.0 1.0</axis>", "<axis>0 0</axis>"),
     r"bad\.osim:\d+: <TransformAxis name='rotation1'>: expected 3 number\(s\) in <axis>"),
    (lambda: broken(osim_v4(), "<coordinates>knee_angle_r</coordinates>",
                    "<coordinates>knee_angle_q</coordinates>"),
     r"bad\.osim:\d+: joint 'knee_r': its rotation axis uses coordinate 'knee_angle_q'"),
    (lambda: broken(osim_v4(), "<x>-2.0944 ", "<x>3.0 "),
     r"bad\.osim:\d+: joint 'knee_r', translation1: a SimmSpline needs two or more points"),
    (lambda: broken(osim_v4(), "<socket_parent>/bodyset/femur_r</socket_parent>",
                    "<socket_parent>/bodyset/nowhere</socket_parent>"),
     r"bad\.osim:\d+: joint 'patellofemoral_r': its parent 'femur_r' is not connected to the "
     r"ground"),
])
def test_a_malformed_osim_is_refused_naming_file_and_line(make, expected, tmp_path):
    path = tmp_path / "bad.osim"
    path.write_text(make())
    with pytest.raises(InputError, match=expected):
        read_osim(path)


def test_a_model_without_two_legs_is_refused_in_one_line(tmp_path):
    one_leg = [j for j in MODEL if not j["name"].endswith("_l")]
    osim, mot = tmp_path / "one_leg.osim", tmp_path / "walk.mot"
    osim.write_text(osim_v4(one_leg))
    write_mot(mot, known_motion())
    with pytest.raises(InputError, match=r"one_leg\.osim: expected a left and a right leg .* "
                                         r"found femur_r"):
        import_mot(mot, osim)


def test_splines_match_their_points_and_slopes():
    """Both spline kinds pass through their points; the not-a-knot-like end condition (the
    cubic through the end points) reproduces a cubic exactly, the natural one a line."""
    x = np.array([0.0, 0.5, 1.2, 2.0, 3.1])
    cubic = 0.3 * x**3 - x**2 + 0.5
    b, c, d = spline_coefficients(x, cubic, natural=False)
    u = np.linspace(0, 3.1, 50)
    k = np.clip(np.searchsorted(x, u, side="right") - 1, 0, 4)
    t = u - x[k]
    assert np.allclose(cubic[k] + t * (b[k] + t * (c[k] + t * d[k])), 0.3 * u**3 - u**2 + 0.5)
    b, c, d = spline_coefficients(x, 2 * x + 1, natural=True)
    assert np.allclose(b, 2) and np.allclose(c, 0) and np.allclose(d, 0)


def test_an_offset_frame_declared_on_a_body_is_found(tmp_path):
    """OpenSim 4 lets a joint name a frame the model declares elsewhere (a body's components)."""
    from ecs_anim.io.opensim_model import body_frames

    moved = broken(osim_v4(), "<CustomJoint name=\"back\"><socket_parent_frame>pelvis_offset",
                   "<CustomJoint name=\"back\"><socket_parent_frame>/bodyset/pelvis/lumbar_base")
    moved = broken(moved, "<Body name=\"pelvis\"><mass>1</mass></Body>",
                   "<Body name=\"pelvis\"><mass>1</mass><components><PhysicalOffsetFrame "
                   "name=\"lumbar_base\"><socket_parent>..</socket_parent><translation>-0.1007 "
                   "0.0815 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>"
                   "</components></Body>")
    q = known_motion()
    centres = []
    for name, text in (("a.osim", osim_v4()), ("b.osim", moved)):
        (tmp_path / name).write_text(text)
        centres.append(body_frames(read_osim(tmp_path / name), q.__getitem__, N_FRAMES)["torso"][2])
    assert np.abs(centres[0] - centres[1]).max() < 1e-12


def test_a_leg_without_toes_gets_its_toe_ahead_of_the_ankle(tmp_path):
    """A model whose feet end at the calcaneus: the toe is filled ahead of the ankle (a foot's
    length at adult proportions, the way the pelvis faces), hips to ankles still exact."""
    no_toes = [j for j in MODEL if not j["name"].startswith("mtp_")]
    osim, mot = tmp_path / "no_toes.osim", tmp_path / "walk.mot"
    osim.write_text(osim_v4(no_toes))
    q = {k: v for k, v in known_motion().items() if not k.startswith("mtp_")}
    write_mot(mot, q)
    motion = import_mot(mot, osim)
    assert motion.info["opensim"]["legs"]["l"] == ["femur_l", "tibia_l", "talus_l", "calcn_l"]
    pose = play_on(motion, motion.source_morphology, True).positions
    expected = joint_centres(known_motion())["talus_r"] @ UP_AXES["y"].T
    assert np.linalg.norm(pose[:, J["ankle_r"]] - expected, axis=-1).max() < 0.001
    foot = np.linalg.norm(pose[:, J["toe_r"]] - pose[:, J["ankle_r"]], axis=-1)
    leg = motion.source_morphology.leg_length
    assert np.all((foot > 0.15 * leg) & (foot < 0.3 * leg))
