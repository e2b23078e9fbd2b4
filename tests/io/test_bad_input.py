"""Malformed inputs: every one gives a clear one-line error naming the file (and line), with no
traceback, and nothing half-written is left behind.

The corpus lives in ``tests/data/bad/`` (see its README.md); damaged ``.nmo`` files are made here
at test time from a fresh import of ``scenarios/motions/walk.bvh``.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from conftest import DATA_DIR, MOTIONS_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import InputError
from ecs_anim.core.morphology import load_morphology_yaml
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.joint_map import map_skeleton
from ecs_anim.motion.clip import HEADER_KEY, load_nmo

BAD = DATA_DIR / "bad"
WALK = MOTIONS_DIR / "walk.bvh"


# --- helpers ---------------------------------------------------------------------------------

def assert_one_line_error(err: BaseException, path: Path | str, line: int | None,
                          fragment: str) -> str:
    """``err`` reads ``path:line: message`` (or ``path: message``) on one line."""
    text = str(err)
    assert "\n" not in text and "\r" not in text, f"error spans several lines: {text!r}"
    assert text.startswith(f"{path}:"), f"error does not start with the file path: {text!r}"
    if line is None:
        assert text.startswith(f"{path}: "), text
    else:
        assert text.startswith(f"{path}:{line}: "), f"expected line {line}: {text!r}"
    assert fragment in text, f"{fragment!r} not in {text!r}"
    if isinstance(err, InputError):
        assert err.path == str(path)
        assert err.line == line
    return text


def cli_error_line(stderr: str, path: Path | str, fragment: str) -> str:
    """The single ``error: path...`` line of a failed command's stderr."""
    assert "Traceback" not in stderr
    errors = [ln for ln in stderr.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1, f"expected one error line, got: {stderr!r}"
    assert errors[0].startswith(f"error: {path}:"), errors[0]
    assert fragment in errors[0], f"{fragment!r} not in {errors[0]!r}"
    return errors[0]


def listing(folder: Path) -> list[str]:
    """Every entry, hidden temporary files included."""
    return sorted(p.name for p in folder.iterdir())


# --- the BVH corpus --------------------------------------------------------------------------

@dataclass(frozen=True)
class BadBvh:
    name: str
    line: int | None  # line the error must name (None: a whole-file problem)
    fragment: str  # part of the expected message
    stage: str = "parse"  # "parse": read_bvh fails; "map": parses, import_bvh fails



BAD_BVH: tuple[BadBvh, ...] = (
    BadBvh("truncated_frames.bvh", 152, "file ends after 3 of 5 frames"),
    BadBvh("truncated_mid_line.bvh", 152, "frame line has 32 values, expected 78"),
    BadBvh("cut_in_hierarchy.bvh", 20, "unexpected end of file: expected CHANNELS"),
    BadBvh("frame_wrong_value_count.bvh", 151, "frame line has 77 values, expected 78"),
    BadBvh("frame_counts_compensate.bvh", 150, "frame line has 79 values, expected 78"),
    BadBvh("channels_count_mismatch.bvh", 17, "CHANNELS of 'knee_l' announces 3 channels but "
           "lists 2"),
    BadBvh("unknown_channel.bvh", 17, "unknown channel 'Wrotation' in 'knee_l'"),
    BadBvh("non_numeric_value.bvh", 151, "expected a number, found '0,456081'"),
    BadBvh("nan_value.bvh", 152, "non-finite value nan in channel Zrotation of joint 'hip_l'"),
    BadBvh("zero_frames.bvh", 148, "no frames (Frames: 0)"),
    BadBvh("missing_frame_time.bvh", 149, "expected 'Frame Time: <seconds>'"),
    BadBvh("negative_frame_time.bvh", 149, "Frame Time must be a positive number of seconds, "
           "found -0.03333333"),
    BadBvh("frames_unicode_digit.bvh", 148, "expected 'Frames: <count>'"),
    BadBvh("missing_left_arm.bvh", None, "nor by its structure (no joint up the spine where two "
           "arms and a neck branch off)", stage="map"),
    BadBvh("offset_two_numbers.bvh", 16, "OFFSET of 'knee_l': expected 3 numbers, found 2"),
    BadBvh("missing_brace.bvh", 15, "expected '{' after 'knee_l', found 'OFFSET"),
    BadBvh("empty.bvh", 1, "unexpected end of file: expected HIERARCHY"),
    BadBvh("garbage.bvh", 1, "expected 'HIERARCHY' at the start of a BVH file"),
)


def _params() -> list[object]:
    return [pytest.param(case, id=case.name) for case in BAD_BVH]


def test_corpus_is_complete():
    """Every BVH in the corpus has a case here, and every case has its file."""
    on_disk = {p.name for p in BAD.glob("*.bvh")}
    assert on_disk == {c.name for c in BAD_BVH}


@pytest.mark.parametrize("case", _params())
def test_bad_bvh_gives_one_line_error_with_file_and_line(case: BadBvh):
    path = BAD / case.name
    if case.stage == "parse":
        with pytest.raises(InputError) as exc:
            read_bvh(path)
    else:
        read_bvh(path)  # well-formed: only the body parts are missing
        with pytest.raises(InputError) as exc:
            import_bvh(path)
    assert_one_line_error(exc.value, path, case.line, case.fragment)
    if case.stage == "map":
        assert "--map" in str(exc.value)


@pytest.mark.parametrize("case", _params())
def test_cli_import_bad_bvh_with_good_one(case: BadBvh, tmp_path, capsys):
    bad = BAD / case.name
    out = tmp_path / "out"
    code = main(["import", str(bad), str(WALK), "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 1
    cli_error_line(captured.err, bad, case.fragment)
    assert "1 of 2 file(s) failed" in captured.err
    assert f"{WALK} -> " in captured.out  # the good file after the bad one is still imported
    # The good one's .nmo is there and readable; nothing (no .nmo, no temp file) for the bad one.
    assert listing(out) == ["walk.nmo"]
    assert load_nmo(out / "walk.nmo").n_frames == 132


# --- damaged .nmo files ------------------------------------------------------------------------

def _rewrite(src: Path, dst: Path, edit: Callable[[dict, dict], None]) -> None:
    """Copy an .nmo, letting ``edit(header, arrays)`` change its content."""
    with np.load(src, allow_pickle=False) as data:
        header = json.loads(str(data[HEADER_KEY]))
        arrays = {k: data[k] for k in data.files if k != HEADER_KEY}
    edit(header, arrays)
    with open(dst, "wb") as f:  # a file object: np.savez would append ".npz" to a name
        payload: dict[str, Any] = {HEADER_KEY: np.array(json.dumps(header)), **arrays}
        np.savez_compressed(f, **payload)


def make_random_bytes(src: Path, dst: Path) -> None:
    dst.write_bytes((BAD / "garbage.nmo").read_bytes())


def make_truncated_half(src: Path, dst: Path) -> None:
    data = src.read_bytes()
    dst.write_bytes(data[: len(data) // 2])


def make_truncated_end(src: Path, dst: Path) -> None:
    dst.write_bytes(src.read_bytes()[:-10])  # the zip's central directory is cut


def make_unknown_version(src: Path, dst: Path) -> None:
    _rewrite(src, dst, lambda header, arrays: header.update(version=99))


def make_missing_array(src: Path, dst: Path) -> None:
    _rewrite(src, dst, lambda header, arrays: arrays.pop("poses/leg_frame"))


def make_not_nmo_zip(src: Path, dst: Path) -> None:
    with open(dst, "wb") as f:
        np.savez(f, positions=np.zeros((2, 3)))


def make_corrupt_deflate(src: Path, dst: Path) -> None:
    """Overwrite the first byte of one member's compressed data with 0xFF (a deflate block of
    the reserved type 3), as a disk or transfer error might."""
    data = bytearray(src.read_bytes())
    with zipfile.ZipFile(src) as z:
        info = z.getinfo("poses/stretch.npy")
    assert info.compress_type == zipfile.ZIP_DEFLATED
    local = info.header_offset
    name_len = int.from_bytes(data[local + 26: local + 28], "little")
    extra_len = int.from_bytes(data[local + 28: local + 30], "little")
    data[local + 30 + name_len + extra_len] = 0xFF
    dst.write_bytes(bytes(data))


def make_npy_renamed(src: Path, dst: Path) -> None:
    with open(dst, "wb") as f:
        np.save(f, np.zeros((2, 3)))



DAMAGED_NMO = [
    pytest.param(make_random_bytes, "not a readable .nmo file (damaged or truncated?)",
                 id="random_bytes"),
    pytest.param(make_truncated_half, "not a readable .nmo file (damaged or truncated?)",
                 id="truncated_half"),
    pytest.param(make_truncated_end, "not a readable .nmo file (damaged or truncated?)",
                 id="truncated_end"),
    pytest.param(make_unknown_version, ".nmo format version 99 is not supported",
                 id="unknown_version"),
    pytest.param(make_missing_array, "array 'leg_frame' is missing", id="missing_array"),
    pytest.param(make_not_nmo_zip, f"not an .nmo file (no {HEADER_KEY} entry)",
                 id="npz_without_header"),
    pytest.param(make_corrupt_deflate, "not a readable .nmo file", id="corrupt_deflate"),
    pytest.param(make_npy_renamed, "not a readable .nmo file", id="npy_renamed"),
]


@pytest.mark.parametrize("make, fragment", DAMAGED_NMO)
def test_damaged_nmo_gives_one_line_error(make, fragment, walk_nmo, tmp_path):
    path = tmp_path / "damaged.nmo"
    make(walk_nmo, path)
    with pytest.raises(InputError) as exc:
        load_nmo(path)
    assert_one_line_error(exc.value, path, None, fragment)


@pytest.mark.parametrize("make, fragment", DAMAGED_NMO)
def test_cli_info_and_export_of_damaged_nmo(make, fragment, walk_nmo, tmp_path, capsys):
    path = tmp_path / "damaged.nmo"
    make(walk_nmo, path)
    before = path.read_bytes()
    for argv in (["info", str(path)], ["info", str(path), "--json"]):
        assert main(argv) == 1
        captured = capsys.readouterr()
        cli_error_line(captured.err, path, fragment)
        assert captured.out == ""
    out = tmp_path / "out"
    for target in ("played.bvh", "played.npz"):
        assert main(["export", str(path), "--morphology", "adult_male",
                     "-o", str(out / target)]) == 1
        cli_error_line(capsys.readouterr().err, path, fragment)
    assert not out.exists() or listing(out) == []
    assert path.read_bytes() == before


# --- YAML joint maps ---------------------------------------------------------------------------

BAD_MAPS = [
    pytest.param("map_unknown_canonical.yaml", 5,
                 "joints.hip_left: unknown canonical joint (did you mean 'hip_l'?)",
                 id="unknown_canonical"),
    pytest.param("map_missing_source_joint.yaml", 5,
                 "joints.wrist_l: no joint 'wrist_left' in", id="missing_source_joint"),
    pytest.param("map_invalid_syntax.yaml", 5, "not valid YAML: mapping values are not allowed",
                 id="invalid_syntax"),
]


@pytest.mark.parametrize("name, line, fragment", BAD_MAPS)
def test_bad_joint_map_names_file_line_and_key(name, line, fragment):
    path = BAD / name
    skeleton = read_bvh(WALK).skeleton
    with pytest.raises(InputError) as exc:
        map_skeleton(skeleton, str(path))
    text = assert_one_line_error(exc.value, path, line, fragment)
    if name == "map_missing_source_joint.yaml":
        assert "closest: 'wrist_l'" in text


@pytest.mark.parametrize("name, line, fragment", BAD_MAPS)
def test_cli_import_with_bad_map_writes_nothing(name, line, fragment, tmp_path, capsys):
    path = BAD / name
    out = tmp_path / "out"
    assert main(["import", str(WALK), "-o", str(out), "--map", str(path)]) == 1
    captured = capsys.readouterr()
    err = cli_error_line(captured.err, path, fragment)
    assert err.startswith(f"error: {path}:{line}: ")
    assert captured.out == ""
    assert not out.exists() or listing(out) == []


# --- morphology YAML ---------------------------------------------------------------------------

BAD_MORPHS = [
    pytest.param("morph_typo_key.yaml", 3, "statue_m: unknown key (did you mean 'stature_m'?)",
                 id="typo_key"),
    pytest.param("morph_negative_length.yaml", 5,
                 "lengths_m.thigh: expected a length in metres between 0.001 and 2, found -0.45",
                 id="negative_length"),
]


@pytest.mark.parametrize("name, line, fragment", BAD_MORPHS)
def test_bad_morphology_names_file_line_and_key(name, line, fragment):
    path = BAD / name
    with pytest.raises(InputError) as exc:
        load_morphology_yaml(path)
    assert_one_line_error(exc.value, path, line, fragment)


@pytest.mark.parametrize("name, line, fragment", BAD_MORPHS)
def test_cli_export_with_bad_morphology_writes_nothing(name, line, fragment, walk_nmo, tmp_path,
                                                       capsys):
    path = BAD / name
    out = tmp_path / "out"
    out.mkdir()
    for target in ("played.bvh", "played.npz"):
        assert main(["export", str(walk_nmo), "--morphology", str(path),
                     "-o", str(out / target)]) == 1
        captured = capsys.readouterr()
        err = cli_error_line(captured.err, path, fragment)
        assert err.startswith(f"error: {path}:{line}: ")
        assert captured.out == ""
    assert listing(out) == []


# --- no silent overwrites ----------------------------------------------------------------------

def test_import_refuses_to_overwrite_without_force(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["import", str(WALK), "-o", str(out)]) == 0
    target = out / "walk.nmo"
    target.write_bytes(b"an older walk.nmo")  # recognisable content
    capsys.readouterr()

    assert main(["import", str(WALK), "-o", str(out)]) == 1
    captured = capsys.readouterr()
    cli_error_line(captured.err, target, "already exists (use --force to overwrite)")
    assert target.read_bytes() == b"an older walk.nmo"
    assert listing(out) == ["walk.nmo"]

    assert main(["import", str(WALK), "-o", str(out), "--force"]) == 0
    assert load_nmo(target).n_frames == 132
    assert listing(out) == ["walk.nmo"]


@pytest.mark.parametrize("suffix", [".bvh", ".npz"])
def test_export_refuses_to_overwrite_without_force(suffix, walk_nmo, tmp_path, capsys):
    target = tmp_path / f"played{suffix}"
    target.write_bytes(b"an older export")
    args = ["export", str(walk_nmo), "--morphology", "adult_female", "-o", str(target)]

    assert main(args) == 1
    captured = capsys.readouterr()
    cli_error_line(captured.err, target, "already exists (use --force to overwrite)")
    assert captured.out == ""
    assert target.read_bytes() == b"an older export"
    assert listing(tmp_path) == [target.name]

    assert main(args + ["--force"]) == 0
    assert target.read_bytes() != b"an older export"
    assert listing(tmp_path) == [target.name]
