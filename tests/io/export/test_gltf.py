"""The glTF export (ecs_anim/gltf.py), read back the way an engine reads it.

The files are read here by a separate reader: pygltflib parses the container and the JSON, and
this file decodes the accessors from the binary chunk itself, applies the animation samplers'
values to the nodes' TRS and composes the node transforms frame by frame (glTF's rules, written
out plainly with 4x4 matrices), then turns Y up into our Z up by the rotation of DESIGN §2
written by hand. Every file is also given to the Khronos glTF validator (npm `gltf-validator`,
run with node): required where CI runs (CI=true), otherwise skipped, saying how to install it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pygltflib
import pytest

from conftest import MOTIONS_DIR, REPO, mocap_files, mocap_params
from ecs_anim.apps.cli.main import main
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINTS
from support.gltf_validator import assert_valid, validate

MM = 1e-3
COMPONENT_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
                    5125: np.uint32, 5126: np.float32}
TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
# Our reading of glTF's axes, independent of the package: (x, y, z) Y up -> (x, -z, y) Z up.
GLTF_TO_OURS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


class GlbReader:
    """A parsed .glb: accessors as numpy arrays, nodes' world transforms per animation frame."""

    def __init__(self, path: Path) -> None:
        self.doc = pygltflib.GLTF2.load_from_bytes(path.read_bytes())
        self.blob = self.doc.binary_blob()
        self.names = [n.name for n in self.doc.nodes]

    def accessor(self, index: int) -> np.ndarray:
        acc = self.doc.accessors[index]
        view = self.doc.bufferViews[acc.bufferView]
        width = TYPE_SIZES[acc.type]
        dtype = np.dtype(COMPONENT_DTYPES[acc.componentType])
        assert view.byteStride in (None, 0, width * dtype.itemsize)  # tightly packed here
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        data = np.frombuffer(self.blob, dtype=dtype, count=acc.count * width, offset=start)
        assert start + data.nbytes <= (view.byteOffset or 0) + view.byteLength
        return data.reshape(acc.count, width) if width > 1 else data

    def world_transforms(self) -> np.ndarray:
        """(frames, nodes, 4, 4) node2world per sampled frame, from the one animation."""
        nodes = self.doc.nodes
        (animation,) = self.doc.animations
        times = self.accessor(animation.samplers[0].input)
        n = len(times)
        trs = {"translation": np.array([n_.translation or [0, 0, 0] for n_ in nodes], float),
               "rotation": np.array([n_.rotation or [0, 0, 0, 1] for n_ in nodes], float),
               "scale": np.array([n_.scale or [1, 1, 1] for n_ in nodes], float)}
        tracks = {k: np.repeat(v[None], n, axis=0) for k, v in trs.items()}
        for channel in animation.channels:
            sampler = animation.samplers[channel.sampler]
            np.testing.assert_array_equal(self.accessor(sampler.input), times)
            tracks[channel.target.path][:, channel.target.node] = self.accessor(sampler.output)
        x, y, z, w = np.moveaxis(tracks["rotation"], -1, 0)
        rot = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ], -2)
        local = np.tile(np.eye(4), (n, len(nodes), 1, 1))
        local[..., :3, :3] = rot * tracks["scale"][..., None, :]
        local[..., :3, 3] = tracks["translation"]
        parent = {c: p for p, node in enumerate(nodes) for c in (node.children or [])}
        world = np.empty_like(local)
        done: set[int] = set()

        def place(k: int) -> None:
            if k in done:
                return
            if k in parent:
                place(parent[k])
                world[:, k] = world[:, parent[k]] @ local[:, k]
            else:
                world[:, k] = local[:, k]
            done.add(k)

        for k in range(len(nodes)):
            place(k)
        return world

    def joint_positions_ours(self, world: np.ndarray) -> np.ndarray:
        """(frames, len(JOINTS), 3): the canonical joints' node origins in our Z-up world."""
        nodes = [self.names.index(j) for j in JOINTS]
        return world[:, nodes][..., :3, 3] @ GLTF_TO_OURS.T


def _export(tmp_path: Path, clip: Path, body: str) -> tuple[Path, Path]:
    assert main(["import", str(clip), "-o", str(tmp_path)]) == 0
    nmo = tmp_path / f"{clip.stem}.nmo"
    glb, npz = tmp_path / f"{clip.stem}_{body}.glb", tmp_path / f"{clip.stem}_{body}.npz"
    assert main(["export", str(nmo), "--morphology", body, "-o", str(glb)]) == 0
    assert main(["export", str(nmo), "--morphology", body, "-o", str(npz)]) == 0
    return glb, npz


@pytest.mark.parametrize("body", ["child", "tall"])
def test_authored_walk_reads_back_equal_to_the_npz_and_passes_the_validator(tmp_path, body):
    glb, npz = _export(tmp_path, MOTIONS_DIR / "walk.bvh", body)
    reader = GlbReader(glb)
    from_npz = np.load(npz)
    got = reader.joint_positions_ours(reader.world_transforms())
    assert got.shape == from_npz["positions"].shape
    error = np.linalg.norm(got - from_npz["positions"], axis=-1).max()
    assert error < 0.1 * MM, f"{error / MM:.4f} mm"
    times = reader.accessor(reader.doc.animations[0].samplers[0].input)
    np.testing.assert_allclose(times, np.arange(len(got)) / float(from_npz["fps"]), atol=1e-6)
    assert_valid([glb])


_ALL_CLIPS: list[Any] = mocap_params("*")  # pytest params, each holding one file (or None)
CLIPS = [p for p in _ALL_CLIPS if p.values[0] is None
         or p.values[0].suffix.lower() in (".bvh", ".c3d")]
BODIES = ["child", "adult_female", "adult_male", "tall", "long_legs", "short_legs"]


@pytest.fixture(scope="module")
def mocap_exports(tmp_path_factory) -> dict[str, tuple[Path, Path]]:
    """Every real clip exported as .glb and .npz, each onto one of the preset bodies in turn."""
    out = tmp_path_factory.mktemp("mocap_glb")
    clips = [p for p in mocap_files("*") if p.suffix.lower() in (".bvh", ".c3d")]
    return {clip.name: _export(out, clip, BODIES[k % len(BODIES)]) for k, clip in enumerate(clips)}


@pytest.mark.parametrize("path", CLIPS)
def test_real_clips_read_back_equal_to_the_npz_on_every_frame(path, mocap_exports):
    glb, npz = mocap_exports[path.name]
    reader = GlbReader(glb)
    error = np.linalg.norm(reader.joint_positions_ours(reader.world_transforms())
                           - np.load(npz)["positions"], axis=-1)  # (frames, joints)
    worst = np.unravel_index(np.argmax(error), error.shape)
    assert error.max() < 0.1 * MM, (f"{JOINTS[worst[1]]} off by {error.max() / MM:.4f} mm "
                                    f"at frame {worst[0]}")


def test_real_clips_pass_the_khronos_validator(mocap_exports):
    if not mocap_exports:
        pytest.skip("real captured clips not found (../shared/mocap)")
    assert_valid([glb for glb, _ in mocap_exports.values()])


def _skinned(reader: GlbReader, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Skinned vertex positions (frames, V, 3) in glTF axes, and each vertex's joint node (V,),
    by glTF's rule: sum of weight * joint2world @ inverse bind @ vertex."""
    (skin,) = reader.doc.skins
    (primitive,) = reader.doc.meshes[0].primitives
    inverse_bind = reader.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    vertices = reader.accessor(primitive.attributes.POSITION).astype(float)
    joints = reader.accessor(primitive.attributes.JOINTS_0)
    weights = reader.accessor(primitive.attributes.WEIGHTS_0).astype(float)
    joint_nodes = np.array(skin.joints)
    skin_matrices = world[:, joint_nodes] @ inverse_bind  # (frames, skin joints, 4, 4)
    homogeneous = np.concatenate([vertices, np.ones((len(vertices), 1))], axis=-1)
    out = np.zeros((world.shape[0], len(vertices), 3))
    for slot in range(4):
        moved = np.einsum("fvij,vj->fvi", skin_matrices[:, joints[:, slot]], homogeneous)[..., :3]
        out += weights[None, :, slot, None] * moved
    return out, joint_nodes[joints[:, 0]]


def test_skinned_capsules_follow_their_bones_on_every_frame(tmp_path):
    """Each vertex stays on its capsule: at one fixed distance (the capsule's radius) from the
    bone it is skinned to, on every frame; the rest pose stands on the ground."""
    glb, _ = _export(tmp_path, MOTIONS_DIR / "walk.bvh", "adult_female")
    reader = GlbReader(glb)
    world = reader.world_transforms()
    skinned, owner = _skinned(reader, world)
    (primitive,) = reader.doc.meshes[0].primitives
    weights = reader.accessor(primitive.attributes.WEIGHTS_0)
    np.testing.assert_allclose(weights.sum(axis=-1), 1.0, atol=1e-6)
    nodes = reader.doc.nodes
    radii = {}
    for joint in np.unique(owner):
        # The bone a joint carries ends at its one child (or end site) that is not at its origin.
        (tip,) = [c for c in nodes[joint].children or []
                  if np.linalg.norm(nodes[c].translation) > 0]
        a, b = world[:, joint, :3, 3], world[:, tip, :3, 3]  # (frames, 3)
        p = skinned[:, owner == joint]  # (frames, v, 3)
        along = np.clip(np.einsum("fvi,fi->fv", p - a[:, None], b - a)
                        / np.sum((b - a) ** 2, axis=-1)[:, None], 0.0, 1.0)
        distance = np.linalg.norm(p - (a[:, None] + along[..., None] * (b - a)[:, None]), axis=-1)
        assert np.ptp(distance) < 0.01 * MM, (reader.names[joint], np.ptp(distance))
        radii[reader.names[joint]] = distance.mean()
    assert len(radii) == 23  # every bone of non-zero length has its capsule
    assert all(0.02 < r < 0.12 for r in radii.values()), radii
    # Triangles face outward: each one's winding agrees with its vertices' normals.
    triangles = reader.accessor(primitive.indices).reshape(-1, 3)
    vertices = reader.accessor(primitive.attributes.POSITION).astype(float)
    normals = reader.accessor(primitive.attributes.NORMAL).astype(float)
    v0, v1, v2 = (vertices[triangles[:, i]] for i in range(3))
    facing = np.einsum("ti,ti->t", np.cross(v1 - v0, v2 - v0), normals[triangles].sum(axis=1))
    assert np.all(facing > 0.0)
    # The rest pose (no animation) is the T-pose standing on the ground, Y up.
    morph = Morphology.preset("adult_female")
    rest = {n.name: np.array(n.translation) for n in nodes if n.translation is not None}
    parent = {c: p for p, node in enumerate(nodes) for c in (node.children or [])}

    def rest_position(k: int) -> np.ndarray:
        return rest[nodes[k].name] + (rest_position(parent[k]) if k in parent else 0.0)

    ankle_y = rest_position(reader.names.index("ankle_l"))[1]
    head_top_y = rest_position(reader.names.index("head_top"))[1]
    assert ankle_y == pytest.approx(morph["ankle_height_l"], abs=1e-9)
    assert head_top_y == pytest.approx(morph.stature, abs=1e-6)


def test_export_to_glb_refuses_to_overwrite_without_force(tmp_path, capsys):
    glb, _ = _export(tmp_path, MOTIONS_DIR / "idle.bvh", "child")
    before = glb.read_bytes()
    nmo = tmp_path / "idle.nmo"
    assert main(["export", str(nmo), "--morphology", "tall", "-o", str(glb)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(glb) in err, err
    assert glb.read_bytes() == before
    assert main(["export", str(nmo), "--morphology", "tall", "-o", str(glb), "--force"]) == 0
    assert glb.read_bytes() != before
    assert GlbReader(glb).doc.scenes[0].name == "tall"


def test_the_validator_reports_a_broken_file(tmp_path):
    """The 0-errors checks above mean something: a file whose time track's recorded bounds are
    wrong is reported."""
    glb, _ = _export(tmp_path, MOTIONS_DIR / "idle.bvh", "child")
    doc = pygltflib.GLTF2.load_from_bytes(glb.read_bytes())
    animation = doc.animations[0]
    doc.accessors[animation.samplers[0].input].max = [1000.0]
    broken = tmp_path / "broken.glb"
    broken.write_bytes(b"".join(doc.save_to_bytes()))
    report = validate([broken])[str(broken)]
    assert report["numErrors"] >= 1
    assert "ACCESSOR_MAX_MISMATCH" in {m["code"] for m in report["messages"]}


def test_run_export_writes_a_valid_glb_per_character_equal_to_its_npz(tmp_path):
    """``run --export`` on a shipped scenario: each character's .glb (adapted to the ground,
    constraints solved) reads back equal to its .npz and passes the validator."""
    out = tmp_path / "reach"
    assert main(["run", str(REPO / "scenarios" / "reach_and_touch.yaml"), "--seconds", "2",
                 "--export", str(out)]) == 0
    glbs = sorted(out.glob("*.glb"))
    assert glbs and len(glbs) == len(sorted(out.glob("*.npz")))
    for glb in glbs:
        reader = GlbReader(glb)
        got = reader.joint_positions_ours(reader.world_transforms())
        error = np.linalg.norm(got - np.load(glb.with_suffix(".npz"))["positions"], axis=-1).max()
        assert error < 0.1 * MM, (glb.name, f"{error / MM:.4f} mm")
    assert_valid(glbs)
