"""A character's ``morphology:``: a preset, a stature with proportions, or segment lengths."""

from __future__ import annotations

import yaml
from yaml import Node

from ecs_anim.core.errors import (
    did_you_mean,
)
from ecs_anim.core.morphology import LENGTH_KEYS, PRESET_SPECS, Morphology, with_lengths_m
from ecs_anim.scenario.reader import YamlReader


def read_morphology(r: YamlReader, node: Node, where: str) -> Morphology:
    if isinstance(node, yaml.ScalarNode):
        name = r.string(node, where)
        if name not in PRESET_SPECS:
            hint = did_you_mean(name, list(PRESET_SPECS))
            raise r.fail(node, where, f"unknown morphology preset {name!r}{hint} (presets: "
                                      f"{', '.join(PRESET_SPECS)}, or a mapping with stature_m / "
                                      "lengths_m)")
        return Morphology.preset(name)
    keys = r.mapping(node, where, {"stature_m": False, "sex": False, "proportions": False,
                                   "leg_scale": False, "mass_kg": False, "lengths_m": False,
                                   "preset": False})
    if "preset" in keys:
        extra = [k for k in keys if k not in ("preset", "lengths_m")]
        if extra:
            raise r.fail(keys[extra[0]], f"{where}.{extra[0]}", "cannot be combined with 'preset' "
                         "(a preset fixes stature, sex and proportions; adjust it with lengths_m)")
        base = read_morphology(r, keys["preset"], f"{where}.preset")
    else:
        sex = r.string(keys["sex"], f"{where}.sex") if "sex" in keys else "male"
        if sex not in ("male", "female"):
            raise r.fail(keys["sex"], f"{where}.sex", f"expected 'male' or 'female', found {sex!r}")
        proportions = r.string(keys["proportions"], f"{where}.proportions") if "proportions" in keys else "adult"
        if proportions not in ("adult", "child"):
            raise r.fail(keys["proportions"], f"{where}.proportions",
                         f"expected 'adult' or 'child', found {proportions!r}")
        base = Morphology.from_stature(
            r.number(keys["stature_m"], f"{where}.stature_m", 0.3, 3.0, "m") if "stature_m" in keys else 1.75,
            sex=sex, proportions=proportions,
            leg_scale=r.number(keys["leg_scale"], f"{where}.leg_scale", 0.5, 1.5) if "leg_scale" in keys else 1.0,
            mass_kg=r.number(keys["mass_kg"], f"{where}.mass_kg", 5, 400, "kg") if "mass_kg" in keys else None,
            name=where)
    if "lengths_m" not in keys:
        return base
    seg_nodes = r.mapping(keys["lengths_m"], f"{where}.lengths_m", {k: False for k in LENGTH_KEYS})
    given = {seg: r.number(v, f"{where}.lengths_m.{seg}", 0.001, 2.0, "m")
             for seg, v in seg_nodes.items()}
    try:
        return with_lengths_m(base, given)
    except ValueError as exc:
        raise r.fail(keys["lengths_m"], f"{where}.lengths_m", str(exc)) from None
