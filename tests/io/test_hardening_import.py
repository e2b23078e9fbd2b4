"""Import hardening (issue 11): ASCII-only BVH numbers, map mistakes blamed on the map, short error
messages whatever the input holds, and structural matching of skeletons whose joint names say
nothing (``Bone_000``...)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, require_mocap
from ecs_anim.core.errors import InputError
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS
from ecs_anim.io.bvh import parse_bvh
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.importing import canonical_clip, import_bvh

WALK = MOTIONS_DIR / "walk.bvh"


def generic_names(text: str) -> str:
    """``text`` with every ROOT and JOINT renamed ``Bone_000``, ``Bone_001``... in file order (End
    Sites stay End Sites), so that no name says what a joint is."""
    numbers = iter(range(1_000_000))
    return re.sub(r"^(\s*(?:ROOT|JOINT)\s+).+?\s*$",
                  lambda m: f"{m.group(1)}Bone_{next(numbers):03d}", text,
                  flags=re.MULTILINE)


# --- item 16: structural matching on topology and rest geometry ------------------------------

#: One clip of each skeleton convention in ../shared/mocap: CMU (MotionBuilder and 3ds Max
#: releases), 3ds Max Biped (no toes, sole End Sites), Bandai (bones along X at rest; bow has
#: non-zero End Sites, walk zero-length ones).
GENERIC_CLIPS = ("cmu_01_01_playground_jumps.bvh", "cmumax_131_02_start_walk_stop_m.bvh",
                 "cmubiped_10_01_kick_30fps.bvh", "bandai_walk.bvh", "bandai_bow.bvh")


def _same_import(text: str, name: str, up: str = "y") -> tuple[np.ndarray, np.ndarray, str]:
    """Canonical positions of the file as it is and with generic names, and how the latter was
    mapped."""
    original = canonical_clip(parse_bvh(text, name), up=up)
    generic = canonical_clip(parse_bvh(generic_names(text), name), up=up)
    return original.positions, generic.positions, generic.joint_map.how


@pytest.mark.parametrize("name", GENERIC_CLIPS)
def test_generic_joint_names_are_matched_by_structure_as_by_the_preset(name):
    require_mocap()
    original, generic, how = _same_import((MOCAP_DIR / name).read_text(), name)
    assert how == "structure (no preset matched)"
    # Every canonical joint, the filled-in ones (toes, hands, head top, spine) included.
    assert np.abs(generic - original).max() < 1e-6


def test_our_own_export_with_generic_names_is_matched_by_structure():
    original, generic, how = _same_import(WALK.read_text(), "walk.bvh")
    assert how.startswith("structure")
    assert np.abs(generic - original).max() < 1e-6


def test_generic_names_on_a_z_up_file_read_with_up_z():
    """A Z-up capture (FAIR's, Mixamo-like names, hands ending in ``LeftHandEnd``) read with
    ``--up z``: the structure finds every joint the preset finds, hands included."""
    require_mocap()
    name = "varied/fair_zup_walk_inch_120hz.bvh"
    if not (MOCAP_DIR / name).exists():
        pytest.skip(f"{name} not in {MOCAP_DIR}")
    original, generic, _ = _same_import((MOCAP_DIR / name).read_text(), name, up="z")
    assert np.abs(generic - original).max() < 1e-6
    # Z up in, Z up out: the head is above the pelvis by most of a trunk in every frame.
    rise = generic[:, JOINT_INDEX["head"], 2] - generic[:, JOINT_INDEX["pelvis"], 2]
    assert rise.min() > 0.4


def test_a_skeleton_no_preset_knows_is_matched_by_structure():
    """An Acclaim ASF conversion (no neck joint; the clavicle joints sit 0.28 m above the thorax
    joint, at the neck base): the names agree with what the structure found."""
    require_mocap()
    path = MOCAP_DIR / "varied" / "asf_noneck_walk_circle_120hz.bvh"
    if not path.exists():
        pytest.skip(f"{path} not there")
    motion = import_bvh(path)
    assert motion.info["joint_map"] == "structure (no preset matched)"
    side_names = {"hip": "femur", "knee": "tibia", "ankle": "foot", "toe": "toes",
                  "shoulder": "humerus", "elbow": "radius", "wrist": "hand"}
    for part, bone in side_names.items():
        for side in "lr":
            assert motion.info["joints"][f"{part}_{side}"] == f"{side}{bone}"
    assert 1.5 < motion.source_morphology.stature < 1.8


# --- item 10: BVH numbers are ASCII ----------------------------------------------------------

WALK_LINES = WALK.read_text().split("\n")
FRAMES_START = 150  # walk.bvh: MOTION on line 147, Frames 148, Frame Time 149, frames from 150


def _with_line(number: int, edit) -> str:
    """walk.bvh with line ``number`` (1-based) replaced by ``edit(line)``."""
    lines = list(WALK_LINES)
    lines[number - 1] = edit(lines[number - 1])
    return "\n".join(lines)


def _second_value(replacement: str):
    """Replace the second number of a line (the root's Y position in a frame line)."""
    def edit(line: str) -> str:
        values = line.split(" ")
        values[1] = replacement
        return " ".join(values)
    return edit


def _parse_error(text: str) -> str:
    with pytest.raises(InputError) as exc:
        parse_bvh(text, "walk.bvh")
    return str(exc.value)


@pytest.mark.parametrize("written", ["1_000", "\u0661\u0662.\u0665", "\uff11\uff12",
                                     "0.8_22245"])
def test_frame_value_not_in_ascii_digits_is_refused_with_file_and_line(written):
    assert float(written) > 0  # Python reads every one of them
    line = FRAMES_START + 1  # frame 2
    message = _parse_error(_with_line(line, _second_value(written)))
    assert message == (f"walk.bvh:{line}: frame line: expected a number in ASCII digits "
                       f"(no '_' separators), found {written!r}")


def test_frame_values_separated_by_a_non_ascii_space_are_refused():
    line = FRAMES_START + 2
    text = _with_line(line, lambda ln: ln.replace(" ", "\u3000", 1))  # ideographic space
    assert _parse_error(text) == (f"walk.bvh:{line}: frame line: numbers must be separated by "
                                  "ASCII spaces or tabs, found '\\u3000' (U+3000)")


def test_offset_and_frame_time_not_in_ascii_digits_are_refused():
    offset = _with_line(16, lambda ln: ln.replace("-0.421998", "-0.421_998"))
    assert WALK_LINES[15].strip() == "OFFSET 0.000000 -0.421998 0.000000"
    assert _parse_error(offset) == ("walk.bvh:16: OFFSET of 'knee_l': expected a number in ASCII "
                                    "digits (no '_' separators), found '-0.421_998'")
    frame_time = _with_line(149, lambda ln: ln.replace("0.0333333333333", "0.0\uff13"))
    assert _parse_error(frame_time) == ("walk.bvh:149: Frame Time: expected a number in ASCII "
                                        "digits (no '_' separators), found '0.0\uff13'")


def test_plain_files_still_parse_alike():
    motion = parse_bvh(WALK.read_text(), "walk.bvh")
    assert motion.channels.shape == (132, 78)
    assert motion.channels[0, 1] == 0.822245


# --- item 12: a map mistake is blamed on the map ---------------------------------------------

def _map_error(tmp_path, entries: str) -> str:
    path = tmp_path / "map.yaml"
    path.write_text("joints:\n" + entries)
    with pytest.raises(InputError) as exc:
        canonical_clip(parse_bvh(WALK.read_text(), "walk.bvh"), map_spec=str(path))
    return str(exc.value).replace(str(path), "map.yaml")


def test_two_canonical_joints_on_one_source_joint_name_the_map_and_both_keys(tmp_path):
    # Before: "walk.bvh: cannot normalize this skeleton: ... lengths must be positive, not
    # ['thigh_l']", blaming the BVH.
    assert _map_error(tmp_path, "  hip_l: hip_l\n  knee_l: hip_l\n") == (
        "map.yaml:3: joints.knee_l: 'hip_l' is already joints.hip_l (line 2); each canonical "
        "joint needs a joint of its own")


def test_a_map_entry_taking_a_joint_the_preset_gave_another_part(tmp_path):
    # Before: imported without a word, the left knee on the right leg.
    assert _map_error(tmp_path, "  knee_l: knee_r\n") == (
        "map.yaml:2: joints.knee_l: 'knee_r' is already knee_r by preset ecs_anim (detected); "
        "each canonical joint needs a joint of its own")


def test_a_map_entry_not_below_its_canonical_parent(tmp_path):
    assert _map_error(tmp_path, "  ankle_l: toe_l\n  toe_l: ankle_l\n") == (
        "map.yaml:3: joints.toe_l: 'ankle_l' (toe_l) is not below 'toe_l' (ankle_l) in walk.bvh")


def test_a_map_entry_at_the_place_of_its_canonical_parent(tmp_path):
    # walk.bvh's pelvis_l helper sits at the pelvis: a hip there makes a zero-length bone.
    assert _map_error(tmp_path, "  hip_l: pelvis_l\n") == (
        "map.yaml:2: joints.hip_l: 'pelvis_l' (hip_l) is at the place of 'pelvis' (pelvis) at rest "
        "(a bone of zero length)")


def test_a_map_that_only_renames_still_imports(tmp_path):
    path = tmp_path / "map.yaml"
    path.write_text("base: ecs_anim\njoints:\n  hip_l: hip_l\n  head_top: head.end\n")
    clip = canonical_clip(parse_bvh(WALK.read_text(), "walk.bvh"), map_spec=str(path))
    reference = canonical_clip(parse_bvh(WALK.read_text(), "walk.bvh"))
    assert np.abs(clip.positions - reference.positions).max() == 0.0


# --- item 13: error messages stay one short line ---------------------------------------------

#: Longest message the house style allows (about 300 characters), the file's path aside.
MESSAGE_CHARS = 300


def _wide_bvh(n_joints: int) -> str:
    """A skeleton of ``n_joints`` joints hanging side by side from the root, one frame."""
    joints = "".join(f"  JOINT Joint_{i:04d}\n  {{\n    OFFSET 0 1 0\n    CHANNELS 1 Zrotation\n"
                     "    End Site\n    {\n      OFFSET 0 1 0\n    }\n  }\n"
                     for i in range(n_joints))
    return ("HIERARCHY\nROOT Root\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
            f"{joints}}}\nMOTION\nFrames: 1\nFrame Time: 0.033333\n"
            + " ".join(["0"] * (3 + n_joints)) + "\n")


def _message(exc: pytest.ExceptionInfo[BaseException], path: object) -> str:
    """The error's text without its ``path:`` prefix, checked to be one line."""
    text = str(exc.value)
    assert "\n" not in text
    return text.removeprefix(f"{path}: ")


def test_a_5000_joint_bvh_that_cannot_be_mapped_gives_a_short_error(tmp_path):
    # Before: one 61,292-character line listing every joint (and each part's closest names).
    path = tmp_path / "wide.bvh"
    path.write_text(_wide_bvh(5000))
    with pytest.raises(InputError) as exc:
        import_bvh(path)
    message = _message(exc, path)
    assert message == ("cannot match the skeleton by its names (no preset fits) nor by its "
                       "structure (no joint where two legs and a spine branch off); "
                       "give --map PRESET or FILE.yaml (joints: {canonical: source_name}); "
                       "presets: ecs-anim import --help")
    assert len(message) < MESSAGE_CHARS


def test_a_5000_joint_bvh_with_a_requested_preset_lists_a_few_missing_parts(tmp_path):
    path = tmp_path / "wide.bvh"
    path.write_text(_wide_bvh(5000))
    with pytest.raises(InputError) as exc:
        import_bvh(path, map_spec="mixamo")
    message = _message(exc, path)
    assert message.startswith("cannot find these body parts in the skeleton: pelvis (closest: ")
    assert "(+13 more) (using preset mixamo (requested)); give --map" in message
    assert len(message) < MESSAGE_CHARS


def test_long_joint_names_are_cut_in_messages():
    name = "Hip" * 2000
    text = _with_line(2, lambda ln: f"ROOT {name}")
    text = text.replace("OFFSET 0.000000 0.000000 0.000000", "OFFSET 0.000000 0.000000", 1)
    assert _parse_error(text) == (f"walk.bvh:4: OFFSET of '{name[:37]}...': expected 3 numbers, "
                                  "found 2")


def _labels_c3d(tmp_path, labels: list[str]):
    from support.c3d_files import write_c3d

    rng = np.random.default_rng(13)
    return write_c3d(tmp_path / "many.c3d", labels, rng.uniform(0.0, 1.0, (5, len(labels), 3)))


#: The most labels one POINT:LABELS parameter holds (its dimensions are bytes); the reader reads
#: no LABELS2.
MAX_LABELS = 255


def test_a_c3d_with_hundreds_of_unknown_labels_gives_a_short_error(tmp_path):
    # Before: the first 60 labels (632 characters).
    labels = [f"M{i:04d}" for i in range(MAX_LABELS)]
    path = _labels_c3d(tmp_path, labels)
    with pytest.raises(InputError) as exc:
        import_c3d(path)
    message = _message(exc, path)
    assert message.startswith("no marker set recognised from the labels ('M0000', 'M0001', "
                              "'M0002', 'M0003', 'M0004', 'M0005' (+249 more)); give --map PRESET")
    assert len(message) < MESSAGE_CHARS


def test_a_c3d_with_hundreds_of_subjects_gives_a_short_error(tmp_path):
    # Before: every subject (3,897 characters).
    labels = [f"Subject{i:04d}:LASI" for i in range(MAX_LABELS)]
    path = _labels_c3d(tmp_path, labels)
    user_map = tmp_path / "map.yaml"
    user_map.write_text("subject: Bob\nmarkers:\n  KNEE_LAT_l: LKNE\n")
    with pytest.raises(InputError) as exc:
        import_c3d(path, str(user_map))
    message = _message(exc, path)
    assert message == ("no markers of subject 'Bob'; subjects in the file: 'Subject0000', "
                       "'Subject0001', 'Subject0002', 'Subject0003', 'Subject0004', 'Subject0005' "
                       "(+249 more)")


def test_a_marker_map_with_an_unknown_role_lists_a_few_roles(tmp_path):
    labels = ["LASI", "RASI", "LPSI", "RPSI"] + [f"M{i:04d}" for i in range(MAX_LABELS - 4)]
    path = _labels_c3d(tmp_path, labels)
    user_map = tmp_path / "map.yaml"
    user_map.write_text("markers:\n  KNEE_LAT_x: M0001\n")
    with pytest.raises(InputError) as exc:
        import_c3d(path, str(user_map))
    # Before: all roles of Plug-in Gait (43 then, 557 characters; 49 with MT1 and MT5, 53 with
    # the front and back shoulder markers).
    message = _message(exc, f"{user_map}:2")
    assert message == ("markers.KNEE_LAT_x: unknown role for plug_in_gait (did you mean "
                       "'KNEE_LAT_r'?); roles: ASIS_l, ASIS_r, PSIS_l, PSIS_r, SACRUM, THIGH_l "
                       "(+47 more) (all in docs/import.md#marker-maps)")


def mixamo_names(text: str) -> str:
    """A CMU MotionBuilder-release clip with Mixamo's names: ``mixamorig:`` before every joint,
    its three spine joints ``Spine, Spine1, Spine2`` (CMU's ``LowerBack, Spine, Spine1``)."""
    spine = {"LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2"}
    return re.sub(r"^(\s*(?:ROOT|JOINT)\s+)(\S+)\s*$",
                  lambda m: f"{m.group(1)}mixamorig:{spine.get(m.group(2), m.group(2))}", text,
                  flags=re.MULTILINE)


def test_a_mapped_spine_joint_at_the_place_of_the_neck_is_placed_between_its_neighbours():
    """CMU's Neck has a zero OFFSET under its top spine joint: with Mixamo's names the mixamo
    preset maps that joint (Spine2) to spine_2, at the neck's place, a spine bone of zero length
    (the import was refused: "lengths must be positive, not ['spine_upper']"). It is placed
    between its neighbours as if unmapped: every joint as the CMU names give it, within 0.1 mm
    (the hand ends aside: the presets take them from different finger joints)."""
    require_mocap()
    path = MOCAP_DIR / "varied" / "cmu_walk_120hz_adelaide.bvh"
    if not path.exists():
        pytest.skip(f"{path} not there")
    text = path.read_text()
    original = canonical_clip(parse_bvh(text, path.name))
    renamed = canonical_clip(parse_bvh(mixamo_names(text), path.name))
    assert renamed.joint_map.how == "preset mixamo (detected)"
    assert not renamed.measured[JOINT_INDEX["spine_2"]]
    body = [JOINT_INDEX[j] for j in JOINTS if j not in ("hand_l", "hand_r")]
    assert np.abs(renamed.positions[:, body] - original.positions[:, body]).max() < 1e-4
