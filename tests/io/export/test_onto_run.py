"""A simulated run onto a user's rig (issue 33, items 1 and 5): ``rec.save(dir, onto=rig)``,
``run --export DIR --onto RIG`` and ``batch --onto RIG``; and FBX rigs (read through ufbx) for
every ``--onto``.

Every output is read back through the rig's own hierarchy by a forward kinematics of the tests'
own (``support/bvh_reference.py`` for BVH, ``support/export_readback.glb_world`` for GLB), never
the exporter's. The FBX rigs are the BVH rigs of ``support/onto_rigs.py`` written as FBX
(``support/fbx_writer.py``) with every bone turned to axes of its own and that turn in its
``PreRotation``, as DCC tools write them, with no take.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, SCENARIOS_DIR
from ecs_anim import Morphology, MotionPlayer, Placement, Simulation, load_scenario
from ecs_anim.apps.cli.main import main
from ecs_anim.core.morphology import bone_lengths_of, leg_length
from ecs_anim.core.skeleton import JOINT_INDEX, N_JOINTS
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.export import Rig, export_motion, load_rig
from ecs_anim.scenario import build_simulation
from support import onto_rigs as rigs
from support.bvh_reference import reference_world
from support.export_readback import GLTF_TO_OURS, glb_world
from support.fbx_writer import Take, turned_joint_frames, write_fbx
from support.gltf_validator import assert_valid

pytest.importorskip("ufbx")

MM = 1e-3
CASES = [(c, pose) for c in rigs.CONVENTIONS for pose in "TA"]
IDS = [f"{c.name}-{pose}" for c, pose in CASES]
#: Parts every convention's rig has (the others' errors are measured where the rig has them).
REQUIRED = {"pelvis", "hip_l", "knee_l", "ankle_l", "toe_l", "spine_1", "spine_2", "neck",
            "head", "shoulder_r", "elbow_r", "wrist_r", "hand_r"}


def convention(name: str) -> rigs.Convention:
    return next(c for c in rigs.CONVENTIONS if c.name == name)


def write_fbx_rig(convention: rigs.Convention, bvh_rig: Path, path: Path,
                  take: bool = False) -> Path:
    """The BVH rig ``bvh_rig`` as an FBX rig: the same joints, names, unit and up axis, each
    bone turned to axes of its own with that turn in its PreRotation; no take unless ``take``
    (then one whose frame turns every joint: a rig's rest pose is its nodes' own transforms,
    not a take's)."""
    motion = read_bvh(bvh_rig)
    if take:
        motion.channels[:] = motion.channels + np.where(
            [c.lower().endswith("rotation") for j in motion.skeleton.joints for c in j.channels],
            10.0, 0.0)
    return write_fbx(path, [Take("Take 001", motion)],
                     joint_frames=turned_joint_frames(len(motion.skeleton.joints)),
                     pre_rotation=True, animated=take, up_axis=2 if convention.up == "z" else 1,
                     unit_scale_factor=100.0 * convention.unit)


def rig_parts(path: Path, rig: Rig, unit: float, up: str) -> dict[str, np.ndarray]:
    """Each body part the rig has, read back from an output onto it: (frames, 3) metres, our
    Z-up world, by the rig joint's name (a BVH in ``unit`` metres and ``up`` axes; a GLB
    is Y up, metres)."""
    if path.suffix == ".glb":
        names, world = glb_world(path)
        positions = world[..., :3, 3] @ GLTF_TO_OURS.T
    else:
        names, positions = reference_world(path, unit, up)
    return {part: positions[:, names.index(rig.names[joint])]
            for part, joint in rig.joint_map.source.items() if joint is not None}


def worst_mm(parts: dict[str, np.ndarray], reference: np.ndarray) -> tuple[float, str]:
    """The largest distance (mm) over frames of any part from ``reference`` (frames, 22, 3),
    and that part."""
    errors = {part: float(np.linalg.norm(found - reference[:, JOINT_INDEX[part]], axis=-1).max())
              for part, found in parts.items()}
    worst = max(errors, key=lambda part: errors[part])
    return errors[worst] / MM, worst


# --- FBX rigs ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fbx_exports(walk, tmp_path_factory) -> dict:
    """The walk onto an FBX rig of each convention in T and A poses, as BVH and GLB, with the
    reference: the walk on the same rig's lengths (``--morphology RIG.bvh``)."""
    folder = tmp_path_factory.mktemp("fbx_onto")
    out: dict = {}
    for c, pose in CASES:
        stem = f"{c.name}_{pose}"
        bvh_rig = rigs.write_rig(c, rigs.body_points(walk, 1.1, pose), folder / f"{stem}.bvh")
        fbx_rig = write_fbx_rig(c, bvh_rig, folder / f"{stem}.fbx")
        _, reference = export_motion(walk, str(bvh_rig), folder / f"{stem}_reference.npz")
        files = {}
        for suffix in (".bvh", ".glb"):
            files[suffix] = folder / f"{stem}_onto_fbx{suffix}"
            export_motion(walk, "source", files[suffix], onto=fbx_rig)
        out[stem] = {"fbx": fbx_rig, "bvh": bvh_rig, "reference": reference.positions,
                     "files": files}
    return out


@pytest.mark.parametrize("suffix", [".bvh", ".glb"])
@pytest.mark.parametrize(("convention", "pose"), CASES, ids=IDS)
def test_an_fbx_rig_read_back_is_the_walk_on_its_lengths(fbx_exports, convention, pose, suffix):
    """Onto an FBX rig (bones with axes of their own and PreRotations), read back through the
    rig's hierarchy: every body part within 1 mm of ``--morphology RIG.bvh`` on every frame
    (0.001 mm measured); the output's joints are the FBX's, by name, in the file's unit and
    axes (Unreal's Z up, the others Y up)."""
    case = fbx_exports[f"{convention.name}_{pose}"]
    rig = load_rig(case["fbx"])
    assert rig.kind == "fbx" and rig.names == load_rig(case["bvh"]).names
    unit, up = (convention.unit, convention.up) if suffix == ".bvh" else (1.0, "y")
    parts = rig_parts(case["files"][suffix], rig, unit, up)
    assert REQUIRED <= set(parts), sorted(REQUIRED - set(parts))
    error, part = worst_mm(parts, case["reference"])
    print(f"{convention.name} {pose} FBX rig -> {suffix}: {error:.4f} mm ({part})")
    assert error < 1.0, f"{part} off by {error:.3f} mm"


def test_an_fbx_rigs_bvh_keeps_its_hierarchy_and_its_glb_passes_the_validator(fbx_exports):
    def words(path: Path) -> list[str]:
        """The hierarchy's words but the channels (read from the FBX they are ZXY)."""
        text = path.read_text().split("MOTION")[0].split()
        return [w for w in text if not w.endswith(("position", "rotation"))]

    for case in fbx_exports.values():
        # The same joints, names and OFFSETs (the FBX's, in its unit) in the same tree.
        assert words(case["files"][".bvh"]) == words(case["bvh"])
    assert_valid([case["files"][".glb"] for case in fbx_exports.values()])


def test_an_fbx_rigs_rest_pose_is_its_nodes_not_a_take(walk, tmp_path):
    """A rig file with a take (its frame turns every joint) is the same rig as without: the
    rest pose is the nodes' own transforms."""
    mixamo = convention("mixamo")
    bvh_rig = rigs.write_rig(mixamo, rigs.body_points(walk, 1.0, "A"), tmp_path / "rig.bvh")
    bare = load_rig(write_fbx_rig(mixamo, bvh_rig, tmp_path / "bare.fbx"))
    animated = load_rig(write_fbx_rig(mixamo, bvh_rig, tmp_path / "taken.fbx", take=True))
    np.testing.assert_allclose(animated.rest_in_world, bare.rest_in_world, atol=1e-9)
    np.testing.assert_allclose(bare.rest_in_world, load_rig(bvh_rig).rest_in_world, atol=1e-9)
    assert bare.morphology.stature == pytest.approx(load_rig(bvh_rig).morphology.stature, abs=1e-9)


# --- a simulated run onto a rig ------------------------------------------------------------------


@pytest.fixture(scope="module")
def rig_files(walk, tmp_path_factory) -> dict[str, Path]:
    """Rigs of three conventions and formats: a Mixamo BVH (A pose), a UE5 GLB (T pose), a
    Daz FBX (A pose), each on the walk's proportions at 1.1 times its stature."""
    folder = tmp_path_factory.mktemp("run_rigs")
    mixamo, ue5, daz = convention("mixamo"), convention("ue5_mannequin"), convention("daz_genesis8")
    daz_bvh = rigs.write_rig(daz, rigs.body_points(walk, 1.1, "A"), folder / "daz.bvh")
    return {"bvh": rigs.write_rig(mixamo, rigs.body_points(walk, 1.1, "A"), folder / "mixamo.bvh"),
            "glb": rigs.write_rig(ue5, rigs.body_points(walk, 1.1, "T"), folder / "ue5.glb"),
            "fbx": write_fbx_rig(daz, daz_bvh, folder / "daz.fbx")}


#: Each rig's file unit (metres) and up axis, for reading its BVH back.
RIG_AXES = {"bvh": (0.01, "y"), "glb": (1.0, "y"), "fbx": (0.01, "y")}


@pytest.mark.parametrize("rig_kind", ["bvh", "glb", "fbx"])
def test_a_character_simulated_on_the_rigs_own_body_is_exported_as_simulated(
        walk, rig_files, tmp_path, rig_kind):
    """The done-when check for a run: a character given the rig's body walks (ground
    adaptation and all), and its files onto the rig, read back, put every body part the rig
    has where the simulation put it, within 1 mm on every frame (0.0001 mm measured)."""
    rig = load_rig(rig_files[rig_kind])
    sim = Simulation({"walk": walk})
    hero = sim.spawn("hero", rig.morphology, MotionPlayer("walk"), Placement((0.5, 2.0)))
    rec = sim.record()
    for _ in range(45):
        sim.step()
    rec.save(tmp_path / "out", onto=rig_files[rig_kind])
    simulated = rec.character(hero).positions
    np.testing.assert_allclose(np.load(tmp_path / "out" / "hero.npz")["positions"], simulated,
                               atol=1e-9)
    for suffix in (".bvh", ".glb"):
        unit, up = RIG_AXES[rig_kind] if suffix == ".bvh" else (1.0, "y")
        parts = rig_parts(tmp_path / "out" / f"hero{suffix}", rig, unit, up)
        error, part = worst_mm(parts, simulated)
        print(f"{rig_kind} rig, the simulated body, {suffix}: {error:.5f} mm ({part})")
        assert error < 1.0, (suffix, part, error)
    assert_valid([tmp_path / "out" / "hero.glb"])


@pytest.fixture(scope="module")
def several_bodies(walk, rig_files, tmp_path_factory) -> dict:
    """A child, an adult and a tall body walking from their own places, the child grown to
    2.0 m over 0.5 s from the 20th tick, saved plain and onto the UE5 GLB rig."""
    folder = tmp_path_factory.mktemp("several")
    sim = Simulation({"walk": walk})
    kid = sim.spawn("kid", Morphology.preset("child"), MotionPlayer("walk"), Placement((0.0, -1.5)))
    sim.spawn("adult", Morphology.preset("adult_male"), MotionPlayer("walk"), Placement((3.0, 0.0)))
    sim.spawn("tall", Morphology.preset("tall"), MotionPlayer("walk"), Placement((-2.0, 1.5)))
    rec = sim.record()
    for tick in range(60):
        if tick == 20:
            sim.set_body(kid, Morphology.preset("tall"), blend_s=0.5)
        sim.step()
    rec.save(folder / "plain")
    rec.save(folder / "onto", onto=rig_files["glb"])
    return {"folder": folder, "rec": rec, "sim": sim, "rig": load_rig(rig_files["glb"])}


@pytest.mark.parametrize("name", ["kid", "adult", "tall"])
def test_bodies_of_every_size_go_onto_the_rigs_own_body(several_bodies, name):
    """Characters of other bodies onto one rig: each is the rig's body (its bones the rig's
    lengths on every frame: the npz), its files read back equal to its npz within 1 mm on
    every frame, it starts where it was simulated, and its path is the simulated one scaled by
    the legs' ratio from there (the kid's through its growth, without a jump)."""
    folder, rig = several_bodies["folder"], several_bodies["rig"]
    recorded = several_bodies["rec"].character(several_bodies["sim"].entity(name))
    onto = np.load(folder / "onto" / f"{name}.npz")["positions"]
    assert onto.shape == (60, N_JOINTS, 3)
    bones = bone_lengths_of(onto)  # (frames, N_LENGTHS), NaN where no bone
    limbs = [k for k in range(bones.shape[1]) if not np.isnan(bones[0, k])]
    np.testing.assert_allclose(bones[:, limbs], np.broadcast_to(
        rig.morphology.lengths[limbs], bones[:, limbs].shape), atol=1e-6)
    for suffix in (".bvh", ".glb"):
        error, part = worst_mm(rig_parts(folder / "onto" / f"{name}{suffix}", rig, 1.0, "y"), onto)
        print(f"{name} onto the UE5 GLB rig, {suffix}: {error:.5f} mm ({part})")
        assert error < 1.0, (suffix, part, error)
    pelvis, simulated = onto[:, JOINT_INDEX["pelvis"]], recorded.positions[:, JOINT_INDEX["pelvis"]]
    np.testing.assert_allclose(pelvis[0, :2], simulated[0, :2], atol=1e-9)
    ratio = leg_length(rig.morphology.lengths) / leg_length(recorded.lengths)  # (frames,)
    steps = np.diff(simulated[:, :2], axis=0) * ratio[1:, None]
    np.testing.assert_allclose(np.diff(pelvis[:, :2], axis=0), steps, atol=1e-9)
    np.testing.assert_allclose(pelvis[:, 2], simulated[:, 2] * ratio, atol=1e-9)


def test_the_rigs_own_document_moves_and_passes_the_validator(several_bodies):
    """Onto a GLB rig each character's ``.glb`` is the rig's document (its nodes) with the
    retargeted animation, valid; without ``onto`` the set is our skeleton, as before."""
    folder = several_bodies["folder"]
    assert_valid(sorted((folder / "onto").glob("*.glb")))
    names, _ = glb_world(folder / "onto" / "kid.glb")
    assert set(several_bodies["rig"].names) <= set(names) and "upperarm_twist_01_l" in names
    assert "ROOT pelvis" in (folder / "plain" / "adult.bvh").read_text()
    assert "ROOT pelvis" not in (folder / "onto" / "adult.bvh").read_text()


# --- the command line ----------------------------------------------------------------------------


def test_run_export_onto_writes_the_bytes_of_rec_save_onto(rig_files, tmp_path, capsys):
    scenario = SCENARIOS_DIR / "reach_and_touch.yaml"
    rig = str(rig_files["fbx"])
    assert main(["run", str(scenario), "--seconds", "0.5", "--export", str(tmp_path / "cli"),
                 "--onto", rig]) == 0
    assert f"onto {rig} (44 joints, preset daz (detected)) to" in capsys.readouterr().out
    loaded = load_scenario(scenario)
    with build_simulation(loaded) as sim:
        rec = sim.record()
        for _ in range(round(0.5 * loaded.fps)):
            sim.step()
        rec.save(tmp_path / "api", onto=rig)
    names = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "api").iterdir()) and len(names) > 3
    for name in names:
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "api" / name).read_bytes(), name
    assert "JOINT lThighBend" in (tmp_path / "cli" / "reacher.bvh").read_text()
    # Never over an earlier set without --force; with it, the set is replaced.
    argv = ["run", str(scenario), "--seconds", "0.5", "--export", str(tmp_path / "cli"), "--onto", rig]
    assert main(argv) != 0
    assert "earlier export" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0


@pytest.mark.parametrize(("argv", "said"), [
    (["--onto", "{rig}"], "--onto {rig}: the rig the export is written onto; give --export DIR"),
    (["--map", "mixamo"], "--map mixamo: matches the joints of an --onto rig; give --onto RIG"),
    (["--export", "{out}", "--onto", "nowhere.glb"], "nowhere.glb: no such rig file"),
    (["--export", "{out}", "--onto", "{rig}", "--map", "mixamo"], "preset"),
])
def test_run_onto_refusals_come_before_the_run(rig_files, tmp_path, capsys, argv, said):
    names = {"rig": rig_files["glb"], "out": tmp_path / "out"}
    assert main(["run", str(SCENARIOS_DIR / "reach_and_touch.yaml"), "--seconds", "0.2",
                 *[a.format(**names) for a in argv]]) != 0
    err = capsys.readouterr().err
    assert said.format(**names) in err and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_batch_onto_a_rig(walk_nmo, rig_files, tmp_path, capsys):
    """``batch --onto``: every job's files onto the rig, read back equal to the job's npz
    within 1 mm; a second run skips them, a changed rig redoes them; a manifest's ``onto:``
    does the same, and a rig it names that is not there is its line's error."""
    rig = load_rig(rig_files["bvh"])
    argv = ["batch", str(walk_nmo), "--bodies", "child,tall", "--formats", "bvh,npz,glb",
            "--out", str(tmp_path / "b"), "--onto", str(rig_files["bvh"]), "--jobs", "1"]
    assert main(argv) == 0
    for body in ("child", "tall"):
        npz = np.load(tmp_path / "b" / "walk" / f"{body}.npz")["positions"]
        for suffix, (unit, up) in ((".bvh", (0.01, "y")), (".glb", (1.0, "y"))):
            error, part = worst_mm(rig_parts(tmp_path / "b" / "walk" / f"{body}{suffix}", rig,
                                             unit, up), npz)
            print(f"batch {body} onto the Mixamo BVH rig, {suffix}: {error:.5f} mm ({part})")
            assert error < 1.0
    assert "mixamorig:LeftUpLeg" in (tmp_path / "b" / "walk" / "tall.bvh").read_text()
    capsys.readouterr()
    assert main(argv) == 0
    assert "2 skipped" in capsys.readouterr().out
    assert main([*argv[:-4], "--onto", str(rig_files["glb"]), "--jobs", "1"]) == 0
    assert "2 ok" in capsys.readouterr().out
    assert "upperarm_l" in (tmp_path / "b" / "walk" / "tall.bvh").read_text()

    manifest = tmp_path / "m.yaml"
    manifest.write_text(f"clips: [{walk_nmo}]\nbodies: [child]\nformats: [bvh]\nout: mb\n"
                        f"onto: {{rig: {rig_files['fbx']}, map: daz}}\n")
    assert main(["batch", "--manifest", str(manifest), "--jobs", "1"]) == 0
    assert "JOINT lShldrBend" in (tmp_path / "mb" / "walk" / "child.bvh").read_text()
    manifest.write_text(f"clips: [{walk_nmo}]\nbodies: [child]\nout: mb\nonto: nowhere.fbx\n")
    capsys.readouterr()
    assert main(["batch", "--manifest", str(manifest), "--jobs", "1"]) != 0
    assert f"{manifest}:4: onto: no such rig file" in capsys.readouterr().err


def test_the_docs_run_and_batch_onto_commands_run_as_written(tmp_path, monkeypatch, capsys):
    """The ``ecs-anim run ... --onto`` and ``ecs-anim batch ... --onto`` lines of
    docs/export.md, cli.md and batch.md run as written (``out/`` in a temporary folder)."""
    commands = [line.strip() for page in ("export.md", "cli.md", "batch.md")
                for line in (REPO / "docs" / page).read_text(encoding="utf-8").splitlines()
                if line.startswith("    ") and line.lstrip().startswith(("ecs-anim run ",
                                                                 "ecs-anim batch "))
                and "--onto" in line and " RIG" not in line]
    assert sum(" run " in c for c in commands) >= 1 and sum(" batch " in c for c in commands) >= 1
    monkeypatch.chdir(REPO)
    for command in commands:
        assert main(command.replace("out/", f"{tmp_path}/out/").split()[1:]) == 0, command
    capsys.readouterr()
    written = sorted(p.relative_to(tmp_path).as_posix() for p in (tmp_path / "out").rglob("*.glb"))
    assert written, "the commands wrote no GLB"
    assert_valid(sorted((tmp_path / "out").rglob("*.glb")))
