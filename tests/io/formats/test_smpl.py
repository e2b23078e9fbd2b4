"""SMPL / SMPL-H / SMPL-X motions (AMASS .npz) with a body-model file: a small model file of
SMPL's layout (made here: the real ones are licensed) and a walk made for it import, and the
motion on its source body gives back the joints a forward kinematics written here puts them at,
within 1 mm on every frame; malformed models and motions are refused in one line naming the file
and the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import InputError
from ecs_anim.core.normalized import decode
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.io.smpl import import_amass, read_amass, read_body_model

MM = 1e-3
#: SMPL's 24 joints at rest (metres, Y up, facing +Z, left at +X), about its neutral model's.
REST = np.array([
    [0.0, 0.93, 0.0], [0.06, 0.84, 0.0], [-0.06, 0.84, 0.0], [0.0, 1.04, -0.01],
    [0.10, 0.46, 0.0], [-0.10, 0.46, 0.0], [0.0, 1.17, 0.0], [0.09, 0.06, -0.04],
    [-0.09, 0.06, -0.04], [0.0, 1.22, 0.02], [0.11, 0.01, 0.08], [-0.11, 0.01, 0.08],
    [0.0, 1.43, -0.01], [0.08, 1.34, 0.0], [-0.08, 1.34, 0.0], [0.0, 1.50, 0.04],
    [0.18, 1.38, -0.01], [-0.18, 1.38, -0.01], [0.44, 1.36, -0.03], [-0.44, 1.36, -0.03],
    [0.70, 1.37, -0.03], [-0.70, 1.37, -0.03], [0.78, 1.36, -0.04], [-0.78, 1.36, -0.04]])
PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
#: Our joints and the SMPL joint each is measured from (the ``smpl`` preset).
MEASURED = {"pelvis": 0, "hip_l": 1, "hip_r": 2, "knee_l": 4, "knee_r": 5, "spine_1": 6,
            "ankle_l": 7, "ankle_r": 8, "spine_2": 9, "toe_l": 10, "toe_r": 11, "neck": 12,
            "head": 15, "shoulder_l": 16, "shoulder_r": 17, "elbow_l": 18, "elbow_r": 19,
            "wrist_l": 20, "wrist_r": 21, "hand_l": 22, "hand_r": 23}
VERTICES_PER_JOINT = 4


def rodrigues(rotvec: np.ndarray) -> np.ndarray:
    """Axis-angle (..., 3) -> matrices (..., 3, 3), written out here."""
    angle = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    k = rotvec / np.maximum(angle[..., 0], 1e-12)
    kx = np.zeros(rotvec.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    kx[..., 1, 0], kx[..., 2, 0], kx[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def write_model(path: Path, n_joints: int = 24, n_betas: int = 10, seed: int = 3) -> Path:
    """A body-model .npz of SMPL's layout: each joint the mean of its own few vertices (so
    ``J_regressor @ v_template`` is :data:`REST`; SMPL-H's finger joints hang off the wrists),
    random shape directions, the SMPL kinematic tree."""
    rng = np.random.default_rng(seed)
    rest, parents = REST, PARENTS
    if n_joints > 24:  # SMPL-H / SMPL-X: fingers (and a jaw and eyes) instead of the hands
        extra = n_joints - 22
        rest = np.concatenate([REST[:22], REST[[20 + k % 2 for k in range(extra)]]
                               + [0.05, 0.0, 0.0] * np.array([[1 - 2 * (k % 2), 0, 0] for k in range(extra)])])
        parents = PARENTS[:22] + [20 + k % 2 for k in range(extra)]
    spread = rng.normal(0.0, 0.02, (n_joints, VERTICES_PER_JOINT, 3))
    spread -= spread.mean(axis=1, keepdims=True)
    template = (rest[:, None] + spread).reshape(-1, 3)
    regressor = np.kron(np.eye(n_joints), np.full((1, VERTICES_PER_JOINT), 1 / VERTICES_PER_JOINT))
    shapedirs = rng.normal(0.0, 0.004, (len(template), 3, n_betas))
    kintree = np.array([[2**32 - 1, *parents[1:]], list(range(n_joints))], dtype=np.int64)
    np.savez(path, v_template=template, shapedirs=shapedirs, J_regressor=regressor,
             kintree_table=kintree, weights=np.ones((len(template), n_joints)) / n_joints,
             posedirs=np.zeros((len(template), 3, 9 * (n_joints - 1))), f=np.zeros((0, 3), int))
    return path


def walk_poses(n_frames: int, n_joints: int = 24, fps: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """A walk as AMASS stores it: poses (F, 3 n_joints), trans (F, 3): the model's Y up turned to
    Z up (+90 deg about X), striding along -Y at 1.2 m/s, legs and arms swinging."""
    t = np.arange(n_frames) / fps
    phase = 2 * np.pi * 0.9 * t
    poses = np.zeros((n_frames, n_joints, 3))
    poses[:, 0, 0] = np.pi / 2
    poses[:, 0, 2] = 0.05 * np.sin(phase)  # the pelvis rolls
    for hip, knee, sign in ((1, 4, 1.0), (2, 5, -1.0)):
        poses[:, hip, 0] = -0.45 * sign * np.sin(phase)
        poses[:, knee, 0] = 0.6 * np.maximum(0.0, np.sin(phase + sign * np.pi / 2))
    for shoulder, elbow, sign in ((16, 18, 1.0), (17, 19, -1.0)):
        poses[:, shoulder, 2] = -sign * 1.2
        poses[:, shoulder, 0] = 0.3 * sign * np.sin(phase)
        poses[:, elbow, 1] = sign * 0.4
    poses[:, 15, 0] = 0.1 * np.sin(2 * phase)
    trans = np.stack([0.02 * np.sin(phase), -1.2 * t, 0.01 * np.cos(2 * phase)], axis=-1)
    return poses.reshape(n_frames, -1), trans


def forward_kinematics(model: Path, motion: Path) -> np.ndarray:
    """The joints (F, n, 3) metres of an AMASS motion on a model file, written out here:
    rest joints from the regressor and betas, then each joint's rotation down the tree."""
    m, a = np.load(model), np.load(motion)
    betas = a["betas"][: m["shapedirs"].shape[-1]]
    rest = m["J_regressor"] @ (m["v_template"] + m["shapedirs"][..., : len(betas)] @ betas)
    parents = [-1, *m["kintree_table"][0, 1:]]
    turn = rodrigues(a["poses"].reshape(len(a["poses"]), -1, 3))
    world_turn, world = [turn[:, 0]], [rest[0] + a["trans"]]
    for j in range(1, len(parents)):
        p = parents[j]
        world.append(world[p] + np.einsum("fab,b->fa", world_turn[p], rest[j] - rest[p]))
        world_turn.append(world_turn[p] @ turn[:, j])
    return np.stack(world, axis=1)


def write_motion(path: Path, n_frames: int = 180, n_joints: int = 24, n_betas: int = 10,
                 fps: float = 60.0, **replace: np.ndarray | None) -> Path:
    """An AMASS .npz of :func:`walk_poses` (keys replaced by ``replace``)."""
    poses, trans = walk_poses(n_frames, n_joints, fps)
    betas = np.random.default_rng(5).normal(0.0, 1.0, n_betas)
    keys: dict[str, Any] = {"poses": poses, "trans": trans, "betas": betas, "mocap_framerate": np.array(fps),
                            "gender": np.array("neutral")} | replace
    np.savez(path, **{k: v for k, v in keys.items() if v is not None})
    return path


def _errors(motion, reference: np.ndarray) -> dict[str, float]:
    """Each measured joint's worst distance (m) from the reference joint it is measured from."""
    joints = decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions
    return {j: float(np.linalg.norm(joints[:, JOINT_INDEX[j]] - reference[:, i], axis=-1).max())
            for j, i in MEASURED.items() if j not in motion.info["filled_in"]}


def test_a_smpl_layout_model_file_round_trips_within_1_mm(tmp_path):
    model = write_model(tmp_path / "model.npz")
    amass = write_motion(tmp_path / "walk_poses.npz")
    motion = import_amass(amass, model)
    assert motion.info["joint_map"] == "preset smpl (requested)"
    assert motion.info["up_axis"] == "z" and motion.fps == 60.0 and motion.n_frames == 180
    assert motion.info["smpl"]["model"] == "SMPL" and motion.info["smpl"]["notes"] == []
    errors = _errors(motion, forward_kinematics(model, amass))
    assert set(errors) == set(MEASURED)  # SMPL's 24 joints measure every part but the head top
    worst = max(errors, key=lambda j: errors[j])
    assert errors[worst] < 1 * MM, f"{worst}: {errors[worst] * 1e3:.4f} mm"


def test_smpl_h_poses_with_sixteen_betas_on_a_ten_beta_model_are_said(tmp_path):
    model = write_model(tmp_path / "smplh.npz", n_joints=52, n_betas=10)
    amass = write_motion(tmp_path / "walk_poses.npz", n_joints=52, n_betas=16)
    motion = import_amass(amass, model)
    assert motion.info["smpl"]["model"] == "SMPL-H"
    assert any("first 10 are used" in n for n in motion.info["smpl"]["notes"])
    assert {"hand_l", "hand_r", "head_top"} <= set(motion.info["filled_in"])
    errors = _errors(motion, forward_kinematics(model, amass))
    assert max(errors.values()) < 1 * MM


def test_the_cli_takes_the_model_with_body_model_and_asks_for_it_in_one_line(tmp_path, capsys):
    model = write_model(tmp_path / "model.npz")
    amass = write_motion(tmp_path / "walk_poses.npz")
    out = tmp_path / "out"
    assert main(["import", str(amass), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert "--body-model" in err[0] and "poses" in err[0], err
    assert main(["import", str(amass), "--body-model", str(model), "-o", str(out)]) == 0
    assert "walk_poses.nmo: 180 frames at 60 fps" in capsys.readouterr().out


@pytest.mark.parametrize(("replace", "expected"), [
    ({"poses": np.zeros((0, 72)), "trans": np.zeros((0, 3))}, "poses: no frame"),
    ({"poses": np.full((180, 72), np.nan)}, r"poses: non-finite values in 180 of 180 frames"),
    ({"poses": np.zeros((180, 70))}, r"poses: shape \(180, 70\)"),
    ({"trans": np.zeros((179, 3))}, r"trans: shape \(179, 3\)"),
    ({"trans": None}, "lacks trans"),
    ({"mocap_framerate": np.array(-1.0)}, "mocap_framerate: -1"),
])
def test_a_malformed_motion_is_refused_naming_file_and_key(replace, expected, tmp_path):
    amass = write_motion(tmp_path / "bad.npz", **replace)
    with pytest.raises(InputError, match=rf"bad\.npz: .*{expected}"):
        read_amass(amass)


def test_a_motion_without_a_rate_asks_for_fps(tmp_path):
    model = write_model(tmp_path / "model.npz")
    amass = write_motion(tmp_path / "norate.npz", mocap_framerate=None)
    with pytest.raises(InputError, match=r"norate\.npz: no frame rate .*--fps"):
        import_amass(amass, model)
    assert import_amass(amass, model, fps=30.0).fps == 30.0


@pytest.mark.parametrize(("edit", "expected"), [
    (lambda d: d.pop("J_regressor"), "lacks J_regressor"),
    (lambda d: d.update(shapedirs=d["shapedirs"][:-1]), r"shapedirs: shape \(95, 3, 10\)"),
    (lambda d: d.update(v_template=d["v_template"] * np.nan), "v_template: holds non-finite"),
    (lambda d: d.update(v_template=d["v_template"] * 1000), "a body model is in metres"),
    (lambda d: d.update(kintree_table=d["kintree_table"][:, ::-1]), "kintree_table: expected"),
])
def test_a_malformed_body_model_is_refused_naming_file_and_key(edit, expected, tmp_path):
    model = write_model(tmp_path / "model.npz")
    data = dict(np.load(model))
    edit(data)
    np.savez(model, **data)
    with pytest.raises(InputError, match=rf"model\.npz: .*{expected}"):
        read_body_model(model)


def test_a_pkl_model_is_refused_saying_to_give_the_npz(tmp_path):
    pkl = tmp_path / "basicmodel_neutral.pkl"
    pkl.write_bytes(b"\x80\x04")
    with pytest.raises(InputError, match=r"basicmodel_neutral\.pkl: a \.pkl body model .*\.npz"):
        read_body_model(pkl)
