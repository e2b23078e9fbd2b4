"""Hardening of scenario YAML and .nmo loading (issue 11 items 9, 11, 14, 15): sizes bounded as
expanded by aliases, big grids read in one go, absurd distances named with their unit, clips
given where a scenario is expected, and .nmo headers checked as strictly as import writes them."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from conftest import DATA_DIR, MOTIONS_DIR, REPO, mocap_files
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import (
    NUMBER_LIST_MIN,
    EcsAnimError,
    InputError,
    NumberList,
    compose_yaml,
    expanded_size,
)
from ecs_anim.core.ground import HeightGrid
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.clip import HEADER_KEY, load_nmo, save_nmo
from ecs_anim.scenario import (
    MAX_GRID_CELLS,
    MAX_GROUND_PARTS,
    MAX_YAML_VALUES,
    YamlReader,
    grounds,
    load_scenario,
)
from ecs_anim.scenario import loader as scenario_module

WALK = MOTIONS_DIR / "walk.bvh"
HEAD = f"duration_s: 1\nmotions:\n  walk: {WALK}\n"
ONE = "characters:\n  - {name: a, morphology: child, motion: walk}\n"


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def load_error(path: Path) -> str:
    with pytest.raises(InputError) as err:
        load_scenario(path)
    message = str(err.value)
    # About 300 characters at most, the file's own path aside (a test folder's path is long).
    assert "\n" not in message and len(message.replace(str(path), "")) < 300, message
    return message


def row(values: list[float] | np.ndarray) -> str:
    return "[" + ", ".join(f"{v:g}" for v in values) + "]"


# --- item 9: sizes as expanded, linear loading ----------------------------------------------------

def test_a_1000_by_1000_grid_loads_without_building_a_node_per_height(tmp_path):
    rng = np.random.default_rng(9)
    heights = np.round(rng.uniform(-0.5, 0.5, (1000, 1000)), 3)
    rows = "\n".join(f"    - {row(r)}" for r in heights)
    path = write(tmp_path, HEAD + f"ground:\n  type: grid\n  cell_m: 0.1\n  heights_m:\n{rows}\n" + ONE)
    root = compose_yaml(path, "scenario", number_lists=True)
    grid_rows = root.value[2][1].value[2][1].value  # ground.heights_m
    assert len(grid_rows) == 1000 and all(isinstance(r, NumberList) for r in grid_rows)
    grid = load_scenario(path).ground
    assert isinstance(grid, HeightGrid)
    np.testing.assert_array_equal(grid._h, heights)
    # The work is one array per row: no scalar node is built for any of the million heights.
    read = YamlReader(str(path))
    np.testing.assert_array_equal(grounds._grid_heights(read, root.value[2][1].value[2][1], "h"),
                                  heights)
    assert all(r._items is None for r in grid_rows)
    assert expanded_size(root, MAX_YAML_VALUES) == 1000 * 1001 + 24


def test_grid_rows_aliased_into_more_heights_than_the_bound_are_refused(tmp_path):
    # 19 KB: one row of 2,000 zeros used 2,100 times is 4.2 million heights.
    path = write(tmp_path, HEAD + "row: &r " + row(np.zeros(2000)) + "\n"
                 "ground:\n  type: grid\n  cell_m: 0.1\n  heights_m: [" + ", ".join(["*r"] * 2100)
                 + "]\n" + ONE)
    path.write_text(path.read_text().replace("row: &r", "description: &r"))
    message = load_error(path)
    assert message == (f"{path}:8: ground.heights_m: at most {MAX_GRID_CELLS:,} heights in the "
                       "ground's grids, found 4,200,000 (an alias counted each time it is used)")


def test_nested_aliases_expanding_to_a_million_grounds_are_refused_at_once(tmp_path):
    # Under 1 KB: six levels of ten parts each are 10**6 grounds.
    levels = ["g0: &g0 {type: plane}"]
    for k in range(1, 7):
        levels.append(f"g{k}: &g{k} {{type: combined, parts: [{', '.join([f'*g{k - 1}'] * 10)}]}}")
    text = HEAD + "description:\n" + "".join(f"  {line}\n" for line in levels) + "ground: *g6\n" + ONE
    path = write(tmp_path, text)
    assert len(text) < 1024
    assert load_error(path) == (f"{path}:1: the scenario holds more than {MAX_YAML_VALUES:,} values "
                                "once its aliases (*name) are expanded, each counted every time it is "
                                "used (docs/scenarios.md, Sizes)")


def test_a_ground_of_too_many_parts_is_refused_at_the_first_one_beyond(tmp_path):
    # 40 x 40 aliased planes: 1,641 grounds, few YAML values.
    text = HEAD + "description:\n  p: &p {type: plane}\n  c: &c {type: combined, parts: [" \
        + ", ".join(["*p"] * 40) + "]}\nground: {type: combined, parts: [" + ", ".join(["*c"] * 40) \
        + "]}\n" + ONE
    path = write(tmp_path, text)
    message = load_error(path)
    # The outer ground, then 24 full inner ones (41 each) come to 985; the 1,001st is inner 25's 15th part.
    assert message == (f"{path}:5: ground.parts[24].parts[14]: a ground has at most "
                       f"{MAX_GROUND_PARTS:,} parts (combined grounds included, an alias counted "
                       "each time it is used)")


def test_expanded_size_counts_each_use_of_an_alias_in_linear_time():
    doubling = ["a0: &a0 [1, 2]"] + [f"a{k}: &a{k} [*a{k - 1}, *a{k - 1}]" for k in range(1, 60)]
    root = yaml.compose("\n".join(doubling))
    assert root is not None
    # a_k expands to 2**(k+2) - 1 values; 2**61 is far beyond the limit, counted in 60 steps.
    assert expanded_size(root.value[3][1], 10**9) == 2**5 - 1
    assert expanded_size(root, 10**9) == 10**9 + 1


@pytest.mark.parametrize("setting, bound, what", [
    ("MAX_CHARACTERS", 2, "characters"), ("MAX_TABLES", 1, "tables")])
def test_lists_beyond_their_bound_are_refused_before_they_are_read(setting, bound, what, tmp_path,
                                                                    monkeypatch):
    monkeypatch.setattr(scenario_module, setting, bound)
    text = HEAD + "characters:\n" + "".join(f"  - {{name: c{i}, morphology: child, motion: walk}}\n"
                                            for i in range(3))
    if what == "tables":
        text += "tables:\n  - {centre_m: [1, 0], size_m: [1, 1], height_m: 0.7}\n" * 1 \
            + "  - {centre_m: [2, 0], size_m: [1, 1], height_m: 0.7}\n"
    path = write(tmp_path, text)
    line = 5 if what == "characters" else 9  # the list's first item
    assert load_error(path) == f"{path}:{line}: {what}: at most {bound:,} {what}, found {bound + 1:,}"


def test_constraints_over_all_characters_are_bounded(tmp_path, monkeypatch):
    monkeypatch.setattr(scenario_module, "MAX_CONSTRAINTS", 5)
    text = HEAD + "description:\n  cs: &cs\n" + "".join(
        f"    - {{name: k{j}, point: wrist_r, target: {{world_m: [0.5, 0, 1]}}}}\n" for j in range(3)) \
        + "characters:\n" + "".join(
            f"  - {{name: c{i}, morphology: child, motion: walk, constraints: *cs}}\n" for i in range(2))
    path = write(tmp_path, text)
    # The line is where the aliased list is written (&cs): one node for all its uses.
    assert load_error(path) == (f"{path}:5: characters[1].constraints: at most 5 constraints over "
                                "all characters, found 6 by here (an alias counted each time it is "
                                "used)")


def test_a_bad_height_in_a_long_row_is_reported_with_its_line_and_place(tmp_path):
    rows = [np.zeros(20) for _ in range(3)]
    lines = [f"    - {row(r)}" for r in rows]
    lines[1] = lines[1].replace("[0, 0, 0", "[0, 0, 5000", 1)  # row 1, column 2
    lines[2] = "    - [0, 0,\n       0, 1e999, " + ", ".join(["0"] * 16) + "]"  # row 2 over two lines
    base = HEAD + "ground:\n  type: grid\n  cell_m: 0.1\n  heights_m:\n"
    path = write(tmp_path, base + "\n".join(lines) + "\n" + ONE)
    assert load_error(path) == (f"{path}:9: ground.heights_m[1][2]: expected a number between -1000 "
                                "and 1000 m, found 5000")
    lines[1] = f"    - {row(rows[1])}"
    path.write_text(base + "\n".join(lines) + "\n" + ONE)
    assert load_error(path) == f"{path}:11: ground.heights_m[2][3]: expected a number in m, found '1e999'"
    lines[2] = "    - [0, 0, 0, high, " + ", ".join(["0"] * 16) + "]"  # not a number list: node by node
    path.write_text(base + "\n".join(lines) + "\n" + ONE)
    assert load_error(path) == f"{path}:10: ground.heights_m[2][3]: expected a number in m, found 'high'"


def test_a_row_of_another_length_is_reported_in_one_short_line(tmp_path):
    rows = [f"    - {row(np.zeros(30))}"] * 500 + [f"    - {row(np.zeros(29))}"]
    path = write(tmp_path, HEAD + "ground:\n  type: grid\n  cell_m: 0.1\n  heights_m:\n"
                 + "\n".join(rows) + "\n" + ONE)
    assert load_error(path) == (f"{path}:8: ground.heights_m: expected a rectangular grid of at least "
                                "2 x 2 heights (rows along y), found 501 rows of lengths 30, 30, 30, "
                                "30, 30, 30 (+495 more)")


@pytest.mark.parametrize("text", [
    'description: "[' + ", ".join(["1"] * 20) + ']"\n',  # inside a quoted text
    "description: grid [" + ", ".join(["1"] * 20) + "] as text\n",  # inside a plain text
    "description: |\n  [" + ",\n  ".join(["1"] * 20) + "]\n",  # inside a block text
    "description: 1  # [" + ", ".join(["1"] * 20) + "]\n",  # in a comment
])
def test_number_lists_inside_texts_and_comments_keep_their_meaning(text, tmp_path):
    path = write(tmp_path, text)
    assert yaml.safe_load(yaml.serialize(compose_yaml(path, "scenario", number_lists=True))) \
        == yaml.safe_load(text)


def test_number_lists_read_in_one_go_equal_yaml_values(tmp_path):
    tokens = ["0", "-0", "+5", "12", "1.5", "-2.", ".25", "-.5", "1e3", "2.5E-2", "1.e2", "0e5",
              "3.000", "+.75", "-1E+2", "7"]
    assert len(tokens) >= NUMBER_LIST_MIN
    path = write(tmp_path, "v: [" + ", ".join(tokens) + "]\n")
    node = compose_yaml(path, "scenario", number_lists=True).value[0][1]
    assert isinstance(node, NumberList)
    read = YamlReader(str(path))
    assert node.numbers.tolist() == [read.number(item, "v") for item in node.value] \
        == [float(t) for t in tokens]
    # octal-looking 012 (YAML 1.1: 10), 1_000 and .nan are not plain: the list is read node by node
    for odd in ("012", "1_000", ".nan"):
        path.write_text("v: [" + ", ".join(tokens + [odd]) + "]\n")
        assert not isinstance(compose_yaml(path, "scenario", number_lists=True).value[0][1], NumberList)


def test_a_file_named_twice_is_read_once(tmp_path):
    path = write(tmp_path, f"duration_s: 1\nmotions:\n  a: {WALK}\n  b: {WALK}\n"
                           "characters:\n  - {name: a, morphology: child, motion: b}\n")
    loaded = load_scenario(path)
    assert loaded.motions["a"] is loaded.motions["b"]
    assert loaded.input_files == (str(path), str(WALK.resolve()))


BAD = DATA_DIR / "bad_scenarios"


@pytest.mark.parametrize("name, line, message", [
    ("aliases_million_grounds.yaml", 1, (f"the scenario holds more than {MAX_YAML_VALUES:,} values once "
     "its aliases (*name) are expanded, each counted every time it is used (docs/scenarios.md, Sizes)")),
    ("aliases_grid_too_big.yaml", 9, (f"ground.heights_m: at most {MAX_GRID_CELLS:,} heights in the "
     "ground's grids, found 4,200,000 (an alias counted each time it is used)")),
    ("target_in_mm.yaml", 13, ("characters[0].constraints[0].target.world_m: the target is 998 m from "
     "the character's start (position_m, on the ground) (at most 100 m); world_m is in metres (was it "
     "given in mm?)")),
])
def test_corpus_cases_fail_in_one_line_from_the_cli(name, line, message, capsys):
    path = BAD / name
    assert load_error(path) == f"{path}:{line}: {message}"
    assert main(["run", str(path)]) == 1
    assert capsys.readouterr().err == f"error: {path}:{line}: {message}\n"


# --- item 14: metres given as millimetres ---------------------------------------------------------

def constrained(target: str, area: str = "") -> str:
    return HEAD + ("characters:\n  - name: a\n    morphology: child\n    motion: walk\n"
                   "    position_m: [1, 2]\n    constraints:\n"
                   f"      - {{name: k, kind: {'area' if area else 'position'}, point: wrist_r, "
                   f"target: {target}{', area: ' + area if area else ''}}}\n")


def test_a_target_in_millimetres_is_refused_naming_the_unit(tmp_path):
    path = write(tmp_path, constrained("{world_m: [550, -150, 820]}"))
    assert load_error(path) == (
        f"{path}:10: characters[0].constraints[0].target.world_m: the target is 998 m from the "
        "character's start (position_m, on the ground) (at most 100 m); world_m is in metres (was it "
        "given in mm?)")
    path.write_text(constrained("{world_m: [90, 2, 40]}"))  # 98.5 m away: kept
    assert load_scenario(path).characters[0].constraints[0].target_in_world == (90.0, 2.0, 40.0)


def test_an_area_in_millimetres_is_refused(tmp_path):
    path = write(tmp_path, constrained("{world_m: [1, 2, 1]}", "{shape: sphere, radius_m: 250}"))
    assert load_error(path) == (f"{path}:10: characters[0].constraints[0].area.radius_m: expected a "
                                "number between 0 and 100 m, found 250")
    path.write_text(constrained("{world_m: [1, 2, 1]}", "{shape: box, high_m: [400, 400, 400]}"))
    assert "area.high_m[0]: expected a number between -100 and 100 m, found 400" in load_error(path)


def test_a_table_far_from_every_character_is_refused(tmp_path):
    path = write(tmp_path, HEAD + ONE + "tables:\n  - {centre_m: [920, 0], size_m: [1.2, 0.8], "
                                        "height_m: 0.92}\n")
    assert load_error(path) == (f"{path}:7: tables[0].centre_m: the table is 920 m from the nearest "
                                "character's position_m (at most 100 m); centre_m is in metres (was it "
                                "given in mm?)")


# --- item 15: an empty team, a clip given as a scenario -------------------------------------------

def test_an_empty_team_is_the_default(tmp_path):
    path = write(tmp_path, HEAD + "characters:\n  - {name: a, morphology: child, motion: walk, "
                                  "team: ''}\n")
    assert load_scenario(path).characters[0].team == ""


def test_a_clip_given_as_a_scenario_says_how_to_play_it(walk_nmo, tmp_path, capsys):
    renamed = tmp_path / "walk.yaml"
    renamed.write_bytes(WALK.read_bytes())
    zipped = tmp_path / "clip.yaml"
    zipped.write_bytes(walk_nmo.read_bytes())
    expected = {
        WALK: f"{WALK}: a scenario YAML was expected, not a BVH clip; to play it, import it "
              "(ecs-anim import 'walk.bvh' -o motions/) or name it in a scenario's motions: "
              "(docs/scenarios.md)",
        renamed: f"{renamed}: a scenario YAML was expected, not a BVH clip; to play it, import it "
                 "(ecs-anim import 'walk.yaml' -o motions/) or name it in a scenario's motions: "
                 "(docs/scenarios.md)",
        walk_nmo: f"{walk_nmo}: a scenario YAML was expected, not an .nmo motion; to play it, name it "
                  "in a scenario's motions: (docs/scenarios.md)",
        zipped: f"{zipped}: a scenario YAML was expected, not a zip archive (an .nmo motion?); to "
                "play it, name it in a scenario's motions: (docs/scenarios.md)",
    }
    for path, message in expected.items():
        assert load_error(path) == message
        for argv in (["run", str(path)], ["view", str(path), "--screenshot", str(tmp_path / "o.png")]):
            assert main(argv) == 1
            assert capsys.readouterr().err.strip().splitlines()[-1] == f"error: {message}"


# --- item 11: .nmo headers checked as import writes them ------------------------------------------

def rewrite(src: Path, dst: Path, edit) -> Path:
    with np.load(src, allow_pickle=False) as data:
        header = json.loads(str(data[HEADER_KEY]))
        arrays = {k: data[k] for k in data.files if k != HEADER_KEY}
    edit(header)
    with open(dst, "wb") as f:
        payload: dict[str, Any] = {HEADER_KEY: np.array(json.dumps(header)), **arrays}
        np.savez_compressed(f, **payload)
    return dst


def set_length(segment: str, value: object):
    return lambda header: header["source_morphology"]["lengths_m"].__setitem__(segment, value)


@pytest.mark.parametrize("edit, message", [
    (lambda h: h.update(version=True), (".nmo format version True is not supported by this ecs_anim "
                                       "(reads versions 1-2); re-import the source clip or upgrade ecs_anim")),
    (lambda h: h.update(version=1.0), (".nmo format version 1.0 is not supported by this ecs_anim "
                                      "(reads versions 1-2); re-import the source clip or upgrade ecs_anim")),
    (set_length("thigh_l", 1000.0), ("damaged .nmo header: source_morphology: segment lengths must be "
                                    "numbers above 0 and at most 3 m, found thigh_l=1000.0")),
    (set_length("forearm_r", "0.25"), ("damaged .nmo header: source_morphology: segment lengths must be "
                                      "numbers above 0 and at most 3 m, found forearm_r='0.25'")),
    (set_length("hand_l", True), ("damaged .nmo header: source_morphology: segment lengths must be "
                                 "numbers above 0 and at most 3 m, found hand_l=True")),
    (set_length("neck", -0.1), ("damaged .nmo header: source_morphology: segment lengths must be "
                               "numbers above 0 and at most 3 m, found neck=-0.1")),
    (lambda h: h["source_morphology"]["lengths_m"].pop("shank_r"),
     "damaged .nmo header: source_morphology: lengths_m lacks shank_r"),
    (lambda h: h["source_morphology"]["lengths_m"].update(
        {k: v * 0.1 for k, v in h["source_morphology"]["lengths_m"].items()}),
     ("damaged .nmo header: source_morphology: the body is 0.175 m tall; import only writes bodies of "
     "0.3-3 m")),
    (lambda h: h["source_morphology"].update(mass_kg=False),
     ("damaged .nmo header: source_morphology: mass_kg must be a number above 0 and at most 1000, "
     "found False")),
    (lambda h: h.update(fps=True), "damaged .nmo header: fps=True, n_frames=132"),
], ids=["version_true", "version_float", "thigh_1000_m", "length_text", "length_bool",
        "length_negative", "length_missing", "stature_0.175_m", "mass_bool", "fps_bool"])
def test_nmo_headers_are_checked_as_import_writes_them(edit, message, walk_nmo, tmp_path):
    path = rewrite(walk_nmo, tmp_path / "bad.nmo", edit)
    with pytest.raises(InputError) as err:
        load_nmo(path)
    assert str(err.value) == f"{path}: {message}"


@pytest.mark.parametrize("clip", sorted((REPO / "scenarios" / "motions").glob("*.bvh"))
                         + mocap_files("**/*.bvh") + mocap_files("**/*.c3d"), ids=lambda p: p.name)
def test_every_imported_clip_passes_the_header_checks(clip, tmp_path):
    try:
        motion = import_c3d(clip) if clip.suffix == ".c3d" else import_bvh(clip)
    except EcsAnimError as exc:  # some clips of ../shared/mocap/varied need options to import
        pytest.skip(f"does not import with the default options: {str(exc)[:120]}")
    save_nmo(motion, tmp_path / "clip.nmo")
    np.testing.assert_array_equal(load_nmo(tmp_path / "clip.nmo").source_morphology.lengths,
                                  motion.source_morphology.lengths)
