"""OpenSim joint angles (.mot): a well-formed file is refused in one line naming its coordinates
and what to import instead (the angles place no joint without the model's segment lengths and
joint frames); a malformed one in one line naming the file and line.
"""

from __future__ import annotations

import pytest

from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import InputError
from ecs_anim.io.opensim_mot import read_mot

HEADER = ("Coordinates\nversion=1\nnRows=2\nnColumns=4\ninDegrees=yes\n\n"
          "Units are S.I. units (second, meters, Newtons, ...)\nendheader\n")
LABELS = "time\tpelvis_tilt\thip_flexion_r\tknee_angle_r\n"
ROWS = "0.00\t1.5\t20.0\t-5.0\n0.01\t1.6\t21.0\t-6.0\n"


def test_a_mot_is_read_then_refused_in_one_line_saying_what_is_missing(tmp_path, capsys):
    mot = tmp_path / "walk.mot"
    mot.write_text(HEADER + LABELS + ROWS)
    read = read_mot(mot)
    assert read.labels == ["pelvis_tilt", "hip_flexion_r", "knee_angle_r"] and read.in_degrees
    assert read.values.shape == (2, 3) and list(read.time_s) == [0.0, 0.01]
    assert main(["import", str(mot), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith(f"error: {mot}: OpenSim joint angles (3 coordinates: pelvis_tilt, "
                             "hip_flexion_r, knee_angle_r; 2 frames)")
    assert err[0].endswith("need the model's segment lengths and joint frames (its .osim), "
                           "which import does not read: import the trial's markers (.trc)")


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
