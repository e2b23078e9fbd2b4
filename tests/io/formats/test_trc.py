"""OpenSim TRC import: the dev C3D files' markers written as TRC (here, in millimetres as OpenSim
writes them, unseen samples as empty cells) import to the same joints as the C3D within 1 mm on
every frame, in the C3D's axes and turned to OpenSim's Y up; malformed files are refused in one
line naming the file and line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import InputError
from ecs_anim.core.normalized import decode
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.reading import C3dMarkers, read_c3d
from ecs_anim.io.trc import import_trc, read_trc
from ecs_anim.scenario import load_scenario

MM = 1e-3
#: Millimetres per unit of POINT:UNITS.
TO_MM = {"m": 1000.0, "cm": 10.0, "mm": 1.0}
#: Z up to OpenSim's Y up: the inverse of DESIGN §2's (x, y, z) -> (x, -z, y).
ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: Dev C3D files whose joint centres come from the markers alone (no subject measurements, which
#: a TRC cannot hold): skin markers in metres, Helen Hayes, Plug-in Gait Y up, clusters.
FILES = ["ktk_tennis_serve.c3d", "varied/mac_helenhayes_events_vjc_60hz.c3d",
         "varied/qualisys_pig_yup_events_100hz.c3d", "c3dorg_eb015pi_gait.c3d"]


def write_trc(path: Path, raw: C3dMarkers, turn: np.ndarray | None = None) -> Path:
    """``raw``'s markers as OpenSim writes a TRC: tab-separated, millimetres, a blank line before
    the frames, an unseen sample as three empty cells; turned by ``turn`` (3, 3) if given."""
    points = raw.positions * TO_MM[raw.units]
    if turn is not None:
        points = points @ turn.T
    n_frames, n_markers, _ = points.shape
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
             "OrigDataStartFrame\tOrigNumFrames",
             f"{raw.rate:g}\t{raw.rate:g}\t{n_frames}\t{n_markers}\tmm\t{raw.rate:g}\t1\t{n_frames}",
             "Frame#\tTime\t" + "\t\t\t".join(raw.labels) + "\t\t",
             "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(n_markers)), ""]
    for f in range(n_frames):
        cells = [str(f + 1), f"{f / raw.rate:.6f}"]
        for m in range(n_markers):
            cells += [f"{v:.6f}" for v in points[f, m]] if raw.valid[f, m] else ["", "", ""]
        lines.append("\t".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def _joints(motion) -> np.ndarray:
    """The motion's joints on its source body (F, J, 3), metres."""
    return decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions


#: Each file in its own axes, and those with Z up also turned to OpenSim's Y up.
CASES = [pytest.param(name, yup, id=f"{Path(name).stem}-{'opensim_yup' if yup else 'file_axes'}")
         for name in FILES for yup in (False, True) if not (yup and "yup" in name)]


@pytest.mark.parametrize(("name", "yup"), CASES)
def test_a_c3d_written_as_trc_imports_to_the_same_joints_within_1_mm(name, yup, tmp_path):
    require_mocap()
    c3d = MOCAP_DIR / name
    raw = read_c3d(c3d)
    up = "y" if yup else None
    trc = write_trc(tmp_path / f"{c3d.stem}.trc", raw, ZUP_TO_YUP if yup else None)
    from_c3d, from_trc = import_c3d(c3d), import_trc(trc)
    assert from_trc.info["marker_set"] == from_c3d.info["marker_set"]
    assert from_trc.info["absent"] == from_c3d.info["absent"]
    assert from_trc.info["up_axis"] == (up or from_c3d.info["up_axis"])
    assert from_trc.n_frames == from_c3d.n_frames
    error = np.linalg.norm(_joints(from_trc) - _joints(from_c3d), axis=-1)
    assert error.max() < 1 * MM, f"{error.max() * 1e3:.4f} mm"


def test_the_cli_imports_a_trc_and_its_c3d_flags(tmp_path, capsys):
    require_mocap()
    raw = read_c3d(MOCAP_DIR / "varied/mac_helenhayes_events_vjc_60hz.c3d")
    trc = write_trc(tmp_path / "walk.trc", raw)
    assert main(["import", str(trc), "-o", str(tmp_path / "out"), "--max-gap", "3",
                 "--trim", "10:"]) == 0
    out = capsys.readouterr().out
    assert "walk.nmo: 141 frames at 60 fps" in out and "unit mm (POINT:UNITS says 'mm')" in out
    assert main(["import", str(trc), "-o", str(tmp_path / "out"), "--force",
                 "--contacts", "events"]) == 1
    assert "a TRC file has none" in capsys.readouterr().err


def _header(n_markers: int = 2, n_frames: int = 2) -> str:
    return ("PathFileType\t4\t(X/Y/Z)\tx.trc\n"
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
            f"100\t100\t{n_frames}\t{n_markers}\tmm\n"
            "Frame#\tTime\tA\t\t\tB\t\t\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n\n")


@pytest.mark.parametrize(("text", "expected"), [
    ("HIERARCHY\n", r"bad\.trc:1: expected a TRC file starting with 'PathFileType'"),
    (_header().replace("\tUnits\n", "\n"), r"bad\.trc:2: the header lacks Units"),
    (_header().replace("100\t100", "fast\t100"), r"bad\.trc:3: DataRate: expected a number"),
    (_header(n_markers=3), r"bad\.trc:4: line 4 names 2 marker\(s\) where NumMarkers says 3"),
    (_header(), r"bad\.trc:\d+: the file holds no frame"),
    (_header() + "1\t0\t1\t2\t3\t4\t5\t6\n", r"bad\.trc:\d+: the file ends after 1 of the 2 frames"),
    (_header() + "1\t0\t1\t2\t3\t4\t5\t6\t7\n", r"bad\.trc:7: a frame of 9 cells where 2 markers make 8"),
    (_header() + "1\t0\t1\t2\tx\t4\t5\t6\n", r"bad\.trc:7: expected a number, found 'x' in column 5"),
    (_header() + "1\t0\tNaN\tNaN\tNaN\n2\t0.01\n", r"bad\.trc: no marker has a sample in any of the 2 frames"),
])
def test_a_malformed_trc_is_refused_naming_file_and_line(text, expected, tmp_path):
    path = tmp_path / "bad.trc"
    path.write_text(text)
    with pytest.raises(InputError, match=expected):
        read_trc(path)



def test_a_scenario_plays_a_trc_named_under_motions(tmp_path):
    require_mocap()
    write_trc(tmp_path / "gait.trc", read_c3d(MOCAP_DIR / "varied/mac_helenhayes_events_vjc_60hz.c3d"))
    (tmp_path / "s.yaml").write_text(
        "duration_s: 1\nmotions:\n  gait: gait.trc\ncharacters:\n"
        "  - {name: a, morphology: {stature_m: 1.2}, motion: gait}\n")
    assert load_scenario(tmp_path / "s.yaml").motions["gait"].info["format_in"] == "trc"
