"""Morphology: a character's segment lengths, masses and centres of mass (DESIGN §4).

Lengths follow :data:`ecs_anim.core.skeleton.LENGTHS` (metres, left and right kept apart so a captured
subject's asymmetry survives the round trip). Masses come from

    de Leva P. (1996), "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
    Journal of Biomechanics 29(9):1223-1230, Table 4 (mass fraction of body mass, and centre of
    mass position as a fraction of segment length from the proximal end).

Stature-based lengths use the proportions of Drillis & Contini (1966), as tabulated in Winter,
"Biomechanics and Motor Control of Human Movement" (4th ed., 2009), Fig. 4.1, with the joint
centres placed as our canonical skeleton defines them (see :func:`Morphology.from_stature`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, UsageError, compose_yaml, did_you_mean
from ecs_anim.core.skeleton import (
    BONE_JOINTS,
    JOINT_INDEX,
    LENGTH_INDEX,
    LENGTHS,
    N_LENGTHS,
    REST_HIP_DIR_LEFT,
)

F64 = NDArray[np.float64]

#: A human stature (m) a body may have: every body we build, read or import lies within.
MIN_STATURE_M, MAX_STATURE_M = 0.3, 3.0

#: de Leva (1996) Table 4: (mass fraction, COM fraction from the proximal end) per sex.
#: Segments are de Leva's; :data:`MASS_SEGMENTS` says which canonical joints bound each one.
DE_LEVA_1996: dict[str, dict[str, tuple[float, float]]] = {
    "male": {
        # Head (vertex-C7 row) and trunk (C7-hip midpoint row) are given from C7 in the table;
        # ours run from the neck base (C7) and from the pelvis (hip midpoint): hence 1 - value.
        "head_neck": (0.0694, 1 - 0.5002),
        "trunk": (0.4346, 1 - 0.5138),
        "upper_arm": (0.0271, 0.5772),
        "forearm": (0.0162, 0.4574),
        "hand": (0.0061, 0.7900),
        "thigh": (0.1416, 0.4095),
        "shank": (0.0433, 0.4459),
        "foot": (0.0137, 0.4415),
    },
    "female": {
        "head_neck": (0.0668, 1 - 0.4841),
        "trunk": (0.4257, 1 - 0.4964),
        "upper_arm": (0.0255, 0.5754),
        "forearm": (0.0138, 0.4559),
        "hand": (0.0056, 0.7474),
        "thigh": (0.1478, 0.3612),
        "shank": (0.0481, 0.4416),
        "foot": (0.0129, 0.4014),
    },
}

#: Body segments for the centre of mass: name -> (proximal joint, distal joint, de Leva segment).
MASS_SEGMENTS: tuple[tuple[str, str, str, str], ...] = (
    ("trunk", "pelvis", "neck", "trunk"),
    ("head_neck", "neck", "head_top", "head_neck"),
    ("thigh_l", "hip_l", "knee_l", "thigh"), ("thigh_r", "hip_r", "knee_r", "thigh"),
    ("shank_l", "knee_l", "ankle_l", "shank"), ("shank_r", "knee_r", "ankle_r", "shank"),
    ("foot_l", "ankle_l", "toe_l", "foot"), ("foot_r", "ankle_r", "toe_r", "foot"),
    ("upper_arm_l", "shoulder_l", "elbow_l", "upper_arm"),
    ("upper_arm_r", "shoulder_r", "elbow_r", "upper_arm"),
    ("forearm_l", "elbow_l", "wrist_l", "forearm"), ("forearm_r", "elbow_r", "wrist_r", "forearm"),
    ("hand_l", "wrist_l", "hand_l", "hand"), ("hand_r", "wrist_r", "hand_r", "hand"),
)
#: The joints bounding each of :data:`MASS_SEGMENTS`: proximal and distal, (n_segments,) each.
_MASS_PROXIMAL = np.array([JOINT_INDEX[s[1]] for s in MASS_SEGMENTS])
_MASS_DISTAL = np.array([JOINT_INDEX[s[2]] for s in MASS_SEGMENTS])

#: Adult lengths as fractions of stature (Drillis & Contini proportions, joint centres ours).
ADULT_PROPORTIONS: dict[str, float] = {
    "pelvis": 0.052,  # pelvis origin to each hip joint centre
    "thigh": 0.245,
    "shank": 0.246,
    "foot": 0.110,  # ankle to ball of the foot
    "ankle_height": 0.039,
    "spine_lower": 0.100,
    "spine_middle": 0.095,
    "spine_upper": 0.085,
    "neck": 0.052,
    "head": 0.128,  # skull base to vertex
    "clavicle": 0.110,  # neck base to shoulder joint centre
    "upper_arm": 0.186,
    "forearm": 0.146,
    "hand": 0.080,  # wrist to knuckles
}
#: A 6-8 year old: relatively larger head and trunk, shorter legs (Snyder et al. 1977 trends).
CHILD_PROPORTIONS: dict[str, float] = ADULT_PROPORTIONS | {
    "thigh": 0.222, "shank": 0.218, "foot": 0.105, "ankle_height": 0.038,
    "spine_lower": 0.105, "spine_middle": 0.100, "spine_upper": 0.090,
    "neck": 0.045, "head": 0.165, "clavicle": 0.100, "upper_arm": 0.175, "forearm": 0.140,
    "hand": 0.078,
}

PRESET_SPECS: dict[str, dict[str, Any]] = {
    "child": {"stature_m": 1.20, "proportions": "child", "sex": "male"},
    "adult_female": {"stature_m": 1.63, "sex": "female"},
    "adult_male": {"stature_m": 1.75, "sex": "male"},
    "tall": {"stature_m": 2.00, "sex": "male"},
    "long_legs": {"stature_m": 1.80, "sex": "female", "leg_scale": 1.12},
    "short_legs": {"stature_m": 1.65, "sex": "male", "leg_scale": 0.88},
}


@dataclass(frozen=True)
class Morphology:
    """A body: segment lengths (metres) and mass parameters.

    Attributes
    ----------
    lengths : (N_LENGTHS,) float64, metres, ordered as :data:`ecs_anim.core.skeleton.LENGTHS`.
    mass_kg : total body mass.
    sex : ``"male"`` or ``"female"``: which column of de Leva's table gives segment masses.
    name : a label for reports.
    """

    lengths: F64
    mass_kg: float = 70.0
    sex: str = "male"
    name: str = "custom"

    def __post_init__(self) -> None:
        lengths = np.asarray(self.lengths, dtype=np.float64)
        if lengths.shape != (N_LENGTHS,):
            raise UsageError(f"Morphology.lengths must have shape ({N_LENGTHS},), got {lengths.shape}")
        if not np.all(np.isfinite(lengths)) or np.any(lengths <= 0.0):
            bad = [n for n, v in zip(LENGTHS, lengths, strict=False) if not (np.isfinite(v) and v > 0)]
            raise UsageError(f"Morphology {self.name!r}: lengths must be positive, not {bad}")
        if self.sex not in DE_LEVA_1996:
            raise UsageError(f"Morphology sex must be 'male' or 'female', got {self.sex!r}")
        if not (np.isfinite(self.mass_kg) and self.mass_kg > 0):
            raise UsageError(f"Morphology mass_kg must be positive, got {self.mass_kg}")
        object.__setattr__(self, "lengths", lengths)

    def __getitem__(self, name: str) -> float:
        return float(self.lengths[LENGTH_INDEX[name]])

    @property
    def leg_length(self) -> float:
        """Mean of left and right thigh + shank: the unit of normalized root positions (m)."""
        return float(leg_length(self.lengths[None])[0])

    @property
    def stature(self) -> float:
        """Standing height (m): ankle height + shank + thigh + hip drop + spine + neck + head."""
        m = self
        side = 0.5 * (m["ankle_height_l"] + m["ankle_height_r"] + m["shank_l"] + m["shank_r"]
                      + m["thigh_l"] + m["thigh_r"])
        # The pelvis origin sits above the hips by the rest hip direction's drop.
        hip_drop = -REST_HIP_DIR_LEFT[2] * 0.5 * (m["pelvis_l"] + m["pelvis_r"])
        return side + hip_drop + m["spine_lower"] + m["spine_middle"] + m["spine_upper"] \
            + m["neck"] + m["head"]

    @classmethod
    def from_stature(cls, stature_m: float, sex: str = "male", proportions: str = "adult",
                     leg_scale: float = 1.0, mass_kg: float | None = None,
                     name: str | None = None) -> Morphology:
        """A body of the given standing height from published proportions.

        ``leg_scale`` lengthens (>1) or shortens the legs; the trunk compensates so the stature
        stays ``stature_m``. ``mass_kg`` defaults to a body-mass index of 22.
        """
        if not (np.isfinite(stature_m) and MIN_STATURE_M <= stature_m <= MAX_STATURE_M):
            hint = " (centimetres? statures are in metres)" if \
                MIN_STATURE_M <= stature_m / 100 <= MAX_STATURE_M else ""
            raise UsageError(f"stature must be between {MIN_STATURE_M:g} and {MAX_STATURE_M:g} m, "
                             f"got {stature_m}{hint}")
        if proportions not in ("adult", "child"):
            raise UsageError(f"proportions must be 'adult' or 'child', got {proportions!r}")
        if not (np.isfinite(leg_scale) and 0.5 <= leg_scale <= 1.5):
            raise UsageError(f"leg_scale must be between 0.5 and 1.5, got {leg_scale}")
        table = CHILD_PROPORTIONS if proportions == "child" else ADULT_PROPORTIONS
        p = dict(table)
        if leg_scale != 1.0:
            leg_gain = (p["thigh"] + p["shank"]) * (leg_scale - 1.0)
            p["thigh"] *= leg_scale
            p["shank"] *= leg_scale
            trunk = p["spine_lower"] + p["spine_middle"] + p["spine_upper"]
            for k in ("spine_lower", "spine_middle", "spine_upper"):
                p[k] *= (trunk - leg_gain) / trunk
        values = {}
        for name_ in LENGTHS:
            base = name_[:-2] if name_.endswith(("_l", "_r")) else name_
            values[name_] = p[base] * stature_m
        # Rescale so the built body has exactly the requested stature.
        m = cls(np.array([values[n] for n in LENGTHS]), 1.0, sex, "tmp")
        lengths = m.lengths * (stature_m / m.stature)
        mass = 22.0 * stature_m**2 if mass_kg is None else mass_kg
        return cls(lengths, float(mass), sex, name or f"stature_{stature_m:.2f}m")

    @classmethod
    def preset(cls, name: str) -> Morphology:
        """One of :data:`PRESET_SPECS` (``child``, ``adult_female``, ``adult_male``, ``tall``,
        ``long_legs``, ``short_legs``)."""
        spec = PRESET_SPECS.get(name)
        if spec is None:
            hint = did_you_mean(name, list(PRESET_SPECS), parenthesized=True)
            raise UsageError(f"unknown morphology preset {name!r}{hint}; presets: "
                           f"{', '.join(PRESET_SPECS)}")
        return cls.from_stature(name=name, **spec)

    def to_dict(self) -> dict[str, Any]:
        """``{name, sex, mass_kg, lengths_m: {segment: metres}}`` (JSON-ready; :meth:`from_dict`)."""
        return {"name": self.name, "sex": self.sex, "mass_kg": self.mass_kg,
                "lengths_m": {n: float(v) for n, v in zip(LENGTHS, self.lengths, strict=False)}}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Morphology:
        """The body :meth:`to_dict` gave (every segment of :data:`LENGTHS` in ``lengths_m``)."""
        lengths = data["lengths_m"]
        return cls(np.array([float(lengths[n]) for n in LENGTHS]), float(data["mass_kg"]),
                   str(data["sex"]), str(data.get("name", "custom")))

    def with_lengths(self, lengths: F64, name: str | None = None) -> Morphology:
        """This body with all its segment lengths replaced: ``lengths`` (N_LENGTHS,) metres."""
        return Morphology(np.asarray(lengths, dtype=np.float64), self.mass_kg, self.sex,
                          name or self.name)


def leg_length(lengths: F64) -> F64:
    """Mean thigh + shank over both sides (m). ``lengths`` (..., N_LENGTHS) -> (...)."""
    i = LENGTH_INDEX
    return 0.5 * (lengths[..., i["thigh_l"]] + lengths[..., i["shank_l"]]
                  + lengths[..., i["thigh_r"]] + lengths[..., i["shank_r"]])


def bone_lengths_of(positions: F64) -> F64:
    """Per-frame length of every bone in :data:`LENGTHS` (NaN for non-bones such as ankle height).

    ``positions`` (..., N_JOINTS, 3) -> (..., N_LENGTHS).
    """
    out = np.full(positions.shape[:-2] + (N_LENGTHS,), np.nan)
    for k, (a, b) in enumerate(BONE_JOINTS):
        if a >= 0:
            out[..., k] = np.linalg.norm(positions[..., b, :] - positions[..., a, :], axis=-1)
    return out


def segment_mass_table(morph: Morphology) -> tuple[F64, F64, np.ndarray, np.ndarray]:
    """Arrays for the centre of mass: masses (kg), COM fraction from proximal, joint indices.

    Returns ``masses`` (n_segments,), ``com_fraction`` (n_segments,), ``proximal`` and
    ``distal`` (n_segments,) int joint indices.
    """
    table = DE_LEVA_1996[morph.sex]
    masses = np.array([table[s[3]][0] for s in MASS_SEGMENTS]) * morph.mass_kg
    frac = np.array([table[s[3]][1] for s in MASS_SEGMENTS])
    return masses, frac, _MASS_PROXIMAL.copy(), _MASS_DISTAL.copy()


def centres_of_mass(positions: F64, masses: F64, com_fraction: F64) -> F64:
    """Whole-body centres of mass of many bodies at once.

    ``positions`` (n, N_JOINTS, 3); ``masses`` and ``com_fraction`` (n, n_segments) from
    :func:`segment_mass_table` of each body (order of :data:`MASS_SEGMENTS`). Returns (n, 3).
    """
    prox, dist = _MASS_PROXIMAL, _MASS_DISTAL
    seg_com = positions[:, prox] + com_fraction[..., None] * (positions[:, dist] - positions[:, prox])
    com: F64 = np.einsum("ns,nsc->nc", masses, seg_com) / masses.sum(axis=1, keepdims=True)
    return com


#: Names a length may be given by: every segment, and each bilateral one without _l/_r.
LENGTH_KEYS: tuple[str, ...] = tuple(LENGTHS) + tuple(sorted(
    {n[:-2] for n in LENGTHS if n.endswith(("_l", "_r"))}))


def with_lengths_m(base: Morphology, lengths_m: dict[str, float]) -> Morphology:
    """``base`` with some segments set (metres): ``thigh`` sets both thighs, ``thigh_l`` one.

    Names must be :data:`LENGTH_KEYS` and values already range-checked by the caller; raises
    ValueError if the result is no human height (0.3 to 3 m).
    """
    lengths = base.lengths.copy()
    for seg, value in lengths_m.items():
        for n in ([seg] if seg in LENGTH_INDEX else [f"{seg}_l", f"{seg}_r"]):
            lengths[LENGTH_INDEX[n]] = float(value)
    body = base.with_lengths(lengths)
    if not MIN_STATURE_M <= body.stature <= MAX_STATURE_M:
        raise UsageError(f"these lengths make a body {body.stature:.2f} m tall; expected 0.3 to 3 m")
    return body


def load_morphology_yaml(path: str | Path) -> Morphology:
    """A morphology from YAML: either ``{stature_m, sex?, proportions?, leg_scale?, mass_kg?}``
    or ``{lengths_m: {segment: metres, ...}, sex?, mass_kg?}`` (bilateral segments may be given
    once without ``_l``/``_r``; unspecified ones come from ``stature_m`` or 1.75 m)."""
    path = str(path)
    node = compose_yaml(path, "morphology")
    if not isinstance(node, yaml.MappingNode):
        raise InputError(path, "a morphology must be a mapping (stature_m: ... or lengths_m: ...)", 1)
    allowed = {"name", "stature_m", "sex", "proportions", "leg_scale", "mass_kg", "lengths_m"}
    top: dict[str, Any] = {}
    lines: dict[str, int] = {}
    for k_node, v_node in node.value:
        key = k_node.value
        line = k_node.start_mark.line + 1
        if key not in allowed:
            hint = did_you_mean(key, sorted(allowed), parenthesized=True)
            raise InputError(path, f"{key}: unknown key{hint}; expected one of "
                                   f"{', '.join(sorted(allowed))}", line)
        lines[key] = line
        try:
            top[key] = yaml.safe_load(yaml.serialize(v_node))
        except yaml.YAMLError as exc:  # e.g. a !!python tag: not plain data
            raise InputError(path, f"{key}: not plain YAML data ({getattr(exc, 'problem', exc)})",
                             line) from None
        if key == "lengths_m":
            if not isinstance(v_node, yaml.MappingNode):
                raise InputError(path, "lengths_m: expected a mapping segment: metres", line)
            for sk, _ in v_node.value:
                lines[f"lengths_m.{sk.value}"] = sk.start_mark.line + 1

    def number(key: str, lo: float, hi: float) -> float:
        value = top[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (lo <= value <= hi):
            raise InputError(path, f"{key}: expected a number between {lo} and {hi}, found "
                                   f"{value!r}", lines[key.split('.')[0] if key not in lines else key])
        return float(value)

    proportions = str(top.get("proportions", "adult"))
    if proportions not in ("adult", "child"):
        raise InputError(path, f"proportions: expected 'adult' or 'child', found {proportions!r}",
                         lines["proportions"])
    sex = str(top.get("sex", "male"))
    if sex not in DE_LEVA_1996:
        raise InputError(path, f"sex: expected 'male' or 'female', found {sex!r}", lines["sex"])
    stature = number("stature_m", MIN_STATURE_M, MAX_STATURE_M) if "stature_m" in top else 1.75
    base = Morphology.from_stature(
        stature, sex=sex, proportions=proportions,
        leg_scale=number("leg_scale", 0.5, 1.5) if "leg_scale" in top else 1.0,
        mass_kg=number("mass_kg", 5.0, 400.0) if "mass_kg" in top else None,
        name=str(top.get("name", Path(path).stem)))
    given: dict[str, float] = {}
    for seg, value in (top.get("lengths_m") or {}).items():
        key = f"lengths_m.{seg}"
        if seg not in LENGTH_KEYS:
            hint = did_you_mean(str(seg), list(LENGTH_KEYS), parenthesized=True)
            raise InputError(path, f"{key}: unknown segment{hint}; segments: {', '.join(LENGTHS)}",
                             lines[key])
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.001 <= value <= 2.0:
            raise InputError(path, f"{key}: expected a length in metres between 0.001 and 2, "
                                   f"found {value!r}", lines[key])
        given[seg] = float(value)
    try:
        return with_lengths_m(base, given)
    except ValueError as exc:
        raise InputError(path, str(exc), lines.get("lengths_m", 1)) from None
