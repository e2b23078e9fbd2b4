"""Which C3D marker is which anatomical landmark: marker-set presets, detection, user maps.

A marker set maps *roles* (our names for landmarks, e.g. ``ASIS_L`` the left anterior superior
iliac spine, ``KNEE_LAT_L`` the lateral femoral epicondyle) to candidate marker labels. Labels
are compared after removing a subject prefix (``Bob:LASI`` -> ``LASI``; ``Bob_LASI`` where
that reading finds more roles, :func:`_subjects`), case, spaces and the separators ``_ . -``,
so ``L_ASIS``, ``l.asis`` and ``LASIS`` are one key. Of a role's candidates the first label
with samples wins, and a label with a duplicate's suffix (``LASI_1``) stands for ``LASI``
where no ``LASI`` has samples (:func:`_resolve`).

Presets:

* ``plug_in_gait`` — Vicon Plug-in Gait full body (LASI, RPSI, LKNE, LTHI, LANK, LTIB, LTOE,
  LHEE, C7, T10, CLAV, STRN, LSHO, LELB, LWRA, LWRB, LFIN, LFHD, ...). A lower-body trial is
  detected as this preset with the unmarked parts absent.
* ``plug_in_gait_lower`` — the same labels, pelvis and legs only (``--map plug_in_gait_lower``
  ignores any upper-body marker, e.g. to import the legs of a trial whose arms are unusable).
* ``helen_hayes`` — Helen Hayes (Kadaba et al. 1990) / Davis (Davis et al. 1991) sets as
  Motion Analysis Cortex (``VSAC``, ``RSHA``, ``R.TO``, ``RWRI``), BTS (``r bar 1``, ``r knee 1``,
  ``r mall``, ``r met``) and Codamotion (``R.ASIS``, ``R.Ant.Fem.``, ``R.Knee``, ``R.Ankle``) write them;
  a label that names both the lateral and the medial marker (Cortex's ``RKNE``) is split by
  position (:func:`ecs_anim.io.c3d.label_roles.split_same_label`).
* ``isb_anatomical`` — anatomical landmarks with ISB (Wu et al. 2002/2005) or CAST
  (Cappozzo et al. 1995) style names: iliac spines (ASIS/PSIS), femoral epicondyles (FLE/FME, LE/ME),
  malleoli (FAL/TAM, LM/MM), metatarsal heads (FM1/FM5, MT1/MT5), calcaneus, acromion (AC),
  humeral epicondyles (HLE/HME, EL/EM; Vicon upper limb ELL/ELM), styloids (RSP/USP, RS/US;
  ulnar head UHE as the Rehazenter/Qualisys set writes it), IJ (SJN), PX (SXS), C7 (CV7), T8.
* ``xsens_mvn`` — the virtual anatomical markers Xsens MVN's C3D exporter writes
  (``pLeftASI``, ``pSacrum``, ``pLeftKneeLatEpicondyle``, ``pLeftLatMalleolus``,
  ``pLeftFirstMetatarsal``, ``pIJ``, ``pC7SpinalProcess``, ``pLeftAcromion``, ...).
* ``animation`` — OptiTrack Motive (Baseline) and Qualisys (Animation) sets, markers near the
  landmarks rather than on them (``WaistLFront``, ``LKneeOut``, ``LToeOut``, ``BackTop``,
  ``LWristOut``, ``HeadL``): centres approximate.
* ``cluster_gait`` — technical marker clusters (c3d.org sample ``Eb015pi``: ``PV1-4`` pelvis,
  ``RTH1-4`` thigh, ``RSK1-4`` shank, ``RFT1-3`` foot; Vicon's lettered ``PELA``, ``LFMA``,
  ``LTBA``, ``LFTA``): no landmarks, so joint centres are found functionally (see
  :mod:`ecs_anim.io.c3d.clusters`); optional greater-trochanter markers (``LGT``) fix a hip's axis.

The landmark presets also read other conventions' spellings of their markers (the Vicon
41-marker set of the CMU captures, MoSh/AMASS, KIT, IOR, the Oxford foot model, RRIS40,
Cortex and OpenSim's example sets), each table saying whose.

Body parts (groups): ``pelvis``, ``leg_l``, ``leg_r``, ``trunk``, ``head``, ``arm_l``, ``arm_r``.
A group whose markers are all missing is *absent* (filled with a neutral pose, recorded in the
file); so is a group with only some of its markers, with one message (under 300 characters)
naming the part, the markers found and those it lacks (``MarkerMap.not_computed``). An arm
needs the acromion (or a marker in front of it and one behind), the lateral elbow and the
wrist (both styloids or one wrist marker); UPA and the medial epicondyle are optional. The file is refused only when neither the pelvis nor
the trunk can be computed.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ecs_anim.core.errors import (
    InputError,
    MappingError,
    compose_yaml,
    did_you_mean,
    listed,
    quoted,
)

MIN_ROLES_DETECTED = 8
GROUPS: tuple[str, ...] = ("pelvis", "leg_l", "leg_r", "trunk", "head", "arm_l", "arm_r")
GROUP_WORDS = {"pelvis": "pelvis", "leg_l": "left leg", "leg_r": "right leg", "trunk": "trunk",
               "head": "head", "arm_l": "left arm", "arm_r": "right arm"}


def label_key(label: str) -> str:
    """Comparison key of a marker label: no subject prefix, upper case, no separators."""
    return re.sub(r"[\s_.\-]", "", label.split(":")[-1]).upper()


def subject_of(label: str) -> str:
    """The subject prefix of a label (``Bob:LASI`` -> ``Bob``), '' when none."""
    return label.rsplit(":", 1)[0].strip() if ":" in label else ""


@dataclass(frozen=True)
class MarkerSet:
    """A marker-set preset.

    roles : role -> candidate labels (compared by :func:`label_key`; first present wins).
    groups : body part -> (required roles, alternatives) where alternatives is a tuple of
        tuples of roles, one of which must be complete (e.g. both PSIS or the sacrum).
    signature : roles of which more than half must be present for the preset to be detected
        (or :data:`MIN_ROLES_DETECTED` roles in all); the preset with most roles found wins.
    """

    name: str
    description: str
    roles: dict[str, tuple[str, ...]]
    groups: dict[str, tuple[tuple[str, ...], tuple[tuple[str, ...], ...]]]
    signature: tuple[str, ...]
    method: str = "landmarks"  # or "functional"
    #: body part -> roles that refine it where marked (not needed to compute it).
    refining: dict[str, tuple[str, ...]] = field(default_factory=dict)


def _sided(table: dict[str, tuple[str, ...]]) -> dict[str, tuple[str, ...]]:
    """Expand ``{"ASIS_{s}": ("{S}ASI",)}`` for both sides; ``{S}`` is L or R, ``{SIDE}`` LEFT
    or RIGHT (``P{SIDE}ASI``: Xsens' ``pLeftASI``), and a label
    written ``*X`` is tried with the side letter or word before and after (``LX``, ``XL``,
    ``LEFTX``, ``XLEFT``). A ``{S}X`` label of three or more letters after the side is also
    tried with the side after it (``ASI_L``: labs that put the side last), as ``*X`` is."""
    out: dict[str, tuple[str, ...]] = {}
    for role, labels in table.items():
        sides = (("l", "L", "LEFT"), ("r", "R", "RIGHT")) if "{s}" in role else ((None, "", ""),)
        for s, letter, word in sides:
            cands: list[str] = []
            for lab in labels:
                if lab.startswith("*"):
                    base = lab[1:]
                    cands += [letter + base, word + base]
                    if len(base) >= 3:  # short suffixed forms would collide (LE+L = L+EL)
                        cands += [base + letter, base + word]
                else:
                    cands.append(lab.format(S=letter, SIDE=word))
                    base = lab.removeprefix("{S}")
                    if base != lab and len(base) >= 3 and "{S}" not in base:
                        cands.append(base + letter)
            out[role.format(s=s) if s else role] = tuple(dict.fromkeys(label_key(c) for c in cands))
    return out


def _groups_sided(table: dict[str, tuple[tuple[str, ...], tuple[tuple[str, ...], ...]]]
                  ) -> dict[str, tuple[tuple[str, ...], tuple[tuple[str, ...], ...]]]:
    out = {}
    for group, (required, alternatives) in table.items():
        if group.endswith("_{s}"):
            for s in "lr":
                out[group.format(s=s)] = (tuple(r.format(s=s) for r in required),
                                          tuple(tuple(r.format(s=s) for r in alt)
                                                for alt in alternatives))
        else:
            out[group] = (required, alternatives)
    return out


# Besides Plug-in Gait's own labels, the Vicon-family spellings of the same markers: the older
# Vicon 41-marker set of the CMU and HDM05 captures (FWT/BWT front and back waist at the
# iliac spines, SHN shin for TIB; CMU mocap data definition), MoSh/AMASS (nghorbani/moshpp
# marker layout: KNI inner knee, ELBIN/IEL inner elbow, FSH/BSH front and back shoulder (its
# SehoonVSK variant, which has no SHO: the acromion at their midpoint), IWR/OWR the thumb- and
# pinkie-side wrist markers, HEL heel: in an ISB set LHE_L would be the lateral epicondyle, but a file
# matches one preset, by its fit) and KIT's whole-body set (motion-database.humanoids.kit.edu:
# AEL lateral epicondyle, WTS/WPS radial and ulnar styloids); MT1/MT5 metatarsal heads as
# CMU's and MoSh's sets add them.
_PIG_ROLES = _sided({
    "ASIS_{s}": ("{S}ASI", "{S}FWT"), "PSIS_{s}": ("{S}PSI", "{S}BWT"), "SACRUM": ("SACR", "SACRUM"),
    "THIGH_{s}": ("{S}THI",), "KNEE_LAT_{s}": ("{S}KNE",),
    "KNEE_MED_{s}": ("{S}KNM", "{S}MKNE", "{S}KNI"),
    "SHANK_{s}": ("{S}TIB", "{S}SHN"), "ANKLE_LAT_{s}": ("{S}ANK",), "ANKLE_MED_{s}": ("{S}MMA", "{S}MED"),
    "HEEL_{s}": ("{S}HEE", "{S}HEL"), "TOE_{s}": ("{S}TOE",),
    "MT1_{s}": ("{S}MT1",), "MT5_{s}": ("{S}MT5",),
    "C7": ("C7",), "T10": ("T10",), "IJ": ("CLAV",), "PX": ("STRN",),
    "ACROMION_{s}": ("{S}SHO",), "ELBOW_LAT_{s}": ("{S}ELB", "{S}AEL"),
    "ELBOW_MED_{s}": ("{S}MEL", "{S}ELBIN", "{S}IEL"),
    "SHOULDER_FRONT_{s}": ("{S}FSH",), "SHOULDER_BACK_{s}": ("{S}BSH",),
    "UPPER_ARM_{s}": ("{S}UPA",), "WRIST_RAD_{s}": ("{S}WRA", "{S}IWR", "{S}WTS"),
    "WRIST_ULN_{s}": ("{S}WRB", "{S}OWR", "{S}WPS"),
    "WRIST_{s}": ("{S}WRI", "{S}WRS"), "HAND_{s}": ("{S}FIN",),
    "HEAD_FRONT_{s}": ("{S}FHD",), "HEAD_BACK_{s}": ("{S}BHD",),
})

# ISB / Van Sint Jan names (IAS, FLE, FAL, FCC, FM1, CAJ, SJN, SXS) with the IOR gait
# protocol's short forms (Leardini et al. 2007, as Visual3D's IOR models list them: CA
# calcaneus, FM/SM/VM first, second and fifth metatarsal heads), the IOR foot model's and
# pyCGM2's FMH/SMH/VMH, the Oxford foot model's D1M/D5M (distal first and fifth metatarsal),
# RRIS40's STER/XPRO/FMT1/HMC2 (the two-letter keys CA, FM, SM, VM are read with the side
# before them only, LCA or LEFT_CA: a side after them would collide, LE+L = L+EL), OpenSim's
# (Rajagopal; AddBiomechanics' XYPH, LEE/MEE elbows), and a Vicon Nexus custom set's (nimble-
# physics' lifting trials: KNEL/KNEM epicondyles, MALL/MALM malleoli lateral and medial,
# CUBL/CUBM the elbow's, WRR/WRU the radial and ulnar wrist).
_ISB_ROLES = _sided({
    "ASIS_{s}": ("*ASIS", "*ASI", "*IAS"), "PSIS_{s}": ("*PSIS", "*PSI", "*IPS"),
    "SACRUM": ("SACR", "SACRUM", "S1"),
    "KNEE_LAT_{s}": ("*FLE", "*LE", "*LFE", "*LEPI", "*LFC", "*KNEL", "*KNE"),
    "KNEE_MED_{s}": ("*FME", "*ME", "*MFE", "*MEPI", "*MFC", "*KNEM", "*KNM"),
    "ANKLE_LAT_{s}": ("*FAL", "*LM", "*LMAL", "*LMA", "*MALL", "*ANKL", "*ANK"),
    "ANKLE_MED_{s}": ("*TAM", "*MM", "*MMAL", "*MMA", "*MALM", "*ANKM"),
    "HEEL_{s}": ("*FCC", "*CAL", "*HEE", "*HEEL", "*CA"),
    "MT1_{s}": ("*FM1", "*MT1", "*MH1", "*MET1", "*M1", "*FM", "*FMH", "*FMT1", "*D1M"),
    "MT5_{s}": ("*FM5", "*MT5", "*MH5", "*MET5", "*M5", "*VM", "*VMH", "*FMT5", "*D5M"),
    "TOE_{s}": ("*FM2", "*MT2", "*MH2", "*TOE", "*SM", "*SMH"),
    "C7": ("C7", "CV7"), "T10": ("T8", "TV8", "T10", "TV10"),
    "IJ": ("IJ", "SJN", "SNJ", "CLAV", "STER"), "PX": ("PX", "SXS", "STRN", "XP", "XPRO", "XYPH"),
    "ACROMION_{s}": ("*AC", "*ACR", "*ACRO", "*CAJ", "*SAE", "*SAJ", "*SHO", "*ACROMION",
                     "*ACROMIUM"),
    # Vicon upper-limb spellings ELL/ELM (lateral/medial); Rehazenter/Qualisys UHE (ulnar head).
    "ELBOW_LAT_{s}": ("*HLE", "*EL", "*LEL", "*LHE", "*ELB", "*ELL", "*LEE", "*CUBL"),
    "ELBOW_MED_{s}": ("*HME", "*EM", "*MEL", "*MHE", "*ELM", "*MEE", "*CUBM"),
    # OpenSim's Rajagopal set marks the distal forearm on the radius and the ulna (FAradius).
    "WRIST_RAD_{s}": ("*RSP", "*RS", "*RST", "*WRA", "*WRR", "*FARADIUS", "*RADIUSSTYLOID"),
    "WRIST_ULN_{s}": ("*USP", "*US", "*UST", "*WRB", "*WRU", "*UHE", "*FAULNA", "*ULNASTYLOID"),
    "WRIST_{s}": ("*WRI", "*WRIST"),
    "MC2_{s}": ("*HM2", "*MC2", "*MCP2", "*HMC2"), "MC5_{s}": ("*HM5", "*MC5", "*MCP5", "*HMC5"),
    # Roles that refine an arm (``_LANDMARK_REFINING``), as the other landmark sets have them:
    # an upper-arm marker and the third metacarpal head (the hand end, as Plug-in Gait's FIN).
    "UPPER_ARM_{s}": ("*UPA",), "HAND_{s}": ("*HM3", "*MC3", "*FIN"),
    "HEAD_FRONT_{s}": ("*FHD",), "HEAD_BACK_{s}": ("*BHD",),
})

# Helen Hayes (Kadaba et al. 1990) and Davis (Davis et al. 1991) sets: wands or thigh/shank
# markers with the lateral epicondyle and malleolus, as Motion Analysis Cortex (VSAC, RSHA,
# R.TO), BTS (Davis protocol: "r bar 1" thigh wand, "r knee 1" lateral epicondyle, "r bar 2"
# shank wand, "r mall", "r met" 5th metatarsal head) and Codamotion gait wands (R.ASIS,
# R.Ant.Fem. = anterior marker of the lateral thigh wand, R.Knee, R.Ankle, R.Toe) spell them.
# Order matters: "r knee 1" (marker) comes before "r knee" (a lab's computed centre in BTS).
# Cortex's POINT:DESCRIPTIONS spell the markers out (V.Sacral, R.Knee.Medial, R.Ankle.Medial);
# Cortex exports (BMClab's walk) also mark R.MT1, R.MT2 and R.MT5, and OpenSim's example sets
# (opensim-models: gait2392, Hamner) R.Knee.Lat, R.Ankle.Med, R.Toe.Tip, R.Acromium, R.Bicep.
# OpenSim's sets have no metatarsal marker, so their toe tip is the toe when nothing nearer
# the metatarsal heads is marked (its last candidate: the toe then sits some 5 cm forward of
# the joint, where the animation sets' forefoot markers place it right).
# Medial epicondyle and malleolus as Plug-in Gait spells them; Cortex writes RKNE / RANK for
# the medial markers too (``c3d_import.split_same_label``: the medial one is nearer the other leg).
_HH_ROLES = _sided({
    "ASIS_{s}": ("{S}ASI", "*ASIS"), "PSIS_{s}": ("{S}PSI", "*PSIS"),
    "SACRUM": ("SACR", "SACRUM", "VSAC", "VSACRAL"),
    "THIGH_{s}": ("{S}THI", "*BAR1", "*WAND1", "*ANTFEM", "*THIGH"),
    "KNEE_LAT_{s}": ("{S}KNE", "*KNEE1", "*KNEE", "*KNEELAT"),
    "KNEE_MED_{s}": ("{S}KNM", "{S}MKNE", "*KNEEMEDIAL", "*KNEEMED"),
    "SHANK_{s}": ("{S}TIB", "{S}SHA", "*BAR2", "*WAND2", "*ANTTIB", "*SHANK"),
    "ANKLE_LAT_{s}": ("{S}ANK", "*MALL", "*ANKLE", "*ANKLELAT"),
    "ANKLE_MED_{s}": ("{S}MMA", "{S}MED", "*ANKLEMEDIAL", "*ANKLEMED"),
    "HEEL_{s}": ("{S}HEE", "*HEEL"), "TOE_{s}": ("{S}TOE", "*TO", "*MET", "*TOE", "*MT2", "*TOETIP"),
    "MT1_{s}": ("*MT1",), "MT5_{s}": ("*MT5",),
    "C7": ("C7",), "T10": ("T10",), "IJ": ("CLAV",), "PX": ("STRN",),
    "ACROMION_{s}": ("{S}SHO", "*SHOULDER", "*SHOULD", "*ACROMION", "*ACROMIUM"),
    "ELBOW_LAT_{s}": ("{S}ELB", "*ELBOW"), "UPPER_ARM_{s}": ("*BICEP",),
    # OpenSim's gait2392 and Hamner sets: wrist markers lateral (radial) and medial (ulnar).
    "WRIST_RAD_{s}": ("*WRISTLAT",), "WRIST_ULN_{s}": ("*WRISTMED",),
    "WRIST_{s}": ("{S}WRI", "*WRIST"), "HAND_{s}": ("{S}FIN",),
    "HEAD_FRONT_{s}": ("{S}FHD",), "HEAD_BACK_{s}": ("{S}BHD",),
})

# Animation marker sets, whose markers sit near the landmarks rather than on them: OptiTrack
# Motive's Baseline set (docs.optitrack.com: WaistLFront on the anterior iliac spine,
# WaistLBack "about 10 cm above the hip joint", BackTop below the neck, Chest mid-sternum,
# WristOut on the distal radius, WristIn on the distal ulna, ToeIn/ToeOut) and Qualisys'
# Animation set (QTM's skeleton solver: HeadL, SpineTop, LKneeOut, LAnkleOut, LHeelBack,
# LForefootIn/Out, LToeTip; its sports variant LKneeIn, LAnkleIn, LElbowIn, LForefoot1/2/5).
# The toe tip marks no joint: the toe comes from the forefoot markers. Chest sits mid-sternum,
# some 10 cm below the jugular notch (IJ) it stands in for, so the neck base (midway between it
# and BackTop) comes out a few cm low and forward: an approximation, unmeasured on a real
# Motive file. The head needs both sides and the forehead (Qualisys' HeadL, HeadR, HeadFront;
# Motive marks one side only).
_ANIMATION_ROLES = _sided({
    "ASIS_{s}": ("WAIST{S}FRONT",), "PSIS_{s}": ("WAIST{S}BACK",), "SACRUM": ("WAISTBACK",),
    "THIGH_{s}": ("{S}THIGH",), "KNEE_LAT_{s}": ("{S}KNEEOUT",), "KNEE_MED_{s}": ("{S}KNEEIN",),
    "SHANK_{s}": ("{S}SHIN", "{S}SHINSIDE"), "ANKLE_LAT_{s}": ("{S}ANKLEOUT",),
    "ANKLE_MED_{s}": ("{S}ANKLEIN",), "HEEL_{s}": ("{S}HEELBACK", "{S}HEEL"),
    "TOE_{s}": ("{S}FOREFOOT2",), "MT1_{s}": ("{S}FOREFOOTIN", "{S}FOREFOOT1", "{S}TOEIN"),
    "MT5_{s}": ("{S}FOREFOOTOUT", "{S}FOREFOOT5", "{S}TOEOUT"),
    "C7": ("BACKTOP", "SPINETOP"), "IJ": ("CHEST",),
    "ACROMION_{s}": ("{S}SHOULDERTOP",), "UPPER_ARM_{s}": ("{S}UARMHIGH",),
    "ELBOW_LAT_{s}": ("{S}ELBOWOUT",), "ELBOW_MED_{s}": ("{S}ELBOWIN",),
    "WRIST_RAD_{s}": ("{S}WRISTOUT",), "WRIST_ULN_{s}": ("{S}WRISTIN",),
    "MC2_{s}": ("{S}HANDIN", "{S}HAND2"), "MC5_{s}": ("{S}HANDOUT",),
    "HEAD_SIDE_{s}": ("HEAD{S}",), "FOREHEAD": ("HEADFRONT",),
})

# Numbered (c3d.org Eb015pi: PV1-4, RTH1-4, RSK1-4, RFT1-3) or lettered as Vicon's cluster
# model writes them (Vicon sample data 2018: PELA-PELD, LFMA-LFMD femur, LTBA-LTBD tibia,
# LFTA-LFTD foot; the first three foot markers are used).
_CLUSTER_ROLES = _sided({
    **{f"PELVIS_{k}": (f"PV{k}", f"PEL{'ABCD'[k - 1]}") for k in range(1, 5)},
    **{f"THIGH_{k}_{{s}}": (f"{{S}}TH{k}", f"{{S}}FM{'ABCD'[k - 1]}") for k in range(1, 5)},
    **{f"SHANK_{k}_{{s}}": (f"{{S}}SK{k}", f"{{S}}TB{'ABCD'[k - 1]}") for k in range(1, 5)},
    **{f"FOOT_{k}_{{s}}": (f"{{S}}FT{k}", f"{{S}}FT{'ABC'[k - 1]}") for k in range(1, 4)},
    # Optional: the greater trochanter (Vicon cluster model LGT/RGT) places a flexion-only hip.
    "TROCHANTER_{s}": ("{S}GT", "{S}GTR", "{S}TROC", "*TROCHANTER"),
})

# Xsens MVN's virtual anatomical markers, as its C3D exporter writes them (the MVN user manual's
# point names: ``p`` + side + landmark): iliac spines (ASI anterior, SIPS posterior; CSI is the
# iliac crest, not used), sacrum, femoral epicondyles, malleoli, heel, first and fifth
# metatarsal heads (pToe is the toe tip, no joint), spinous processes (C7, T8), the sternum's
# ends (IJ, PX), acromion, humeral epicondyles and styloids, and the head's sides at the ears
# (auricularis) with the back of the head.
_XSENS_ROLES = _sided({
    "ASIS_{s}": ("P{SIDE}ASI",), "PSIS_{s}": ("P{SIDE}SIPS",), "SACRUM": ("PSACRUM",),
    "KNEE_LAT_{s}": ("P{SIDE}KNEELATEPICONDYLE",), "KNEE_MED_{s}": ("P{SIDE}KNEEMEDEPICONDYLE",),
    "ANKLE_LAT_{s}": ("P{SIDE}LATMALLEOLUS",), "ANKLE_MED_{s}": ("P{SIDE}MEDMALLEOLUS",),
    "HEEL_{s}": ("P{SIDE}HEELFOOT", "P{SIDE}HEELCENTER"),
    "MT1_{s}": ("P{SIDE}FIRSTMETATARSAL",), "MT5_{s}": ("P{SIDE}FIFTHMETATARSAL",),
    "C7": ("PC7SPINALPROCESS",), "T10": ("PT8SPINALPROCESS", "PT12SPINALPROCESS"),
    "IJ": ("PIJ",), "PX": ("PPX",),
    "ACROMION_{s}": ("P{SIDE}ACROMION",),
    "ELBOW_LAT_{s}": ("P{SIDE}ARMLATEPICONDYLE",), "ELBOW_MED_{s}": ("P{SIDE}ARMMEDEPICONDYLE",),
    "WRIST_RAD_{s}": ("P{SIDE}RADIALSTYLOID",), "WRIST_ULN_{s}": ("P{SIDE}ULNARSTYLOID",),
    "HEAD_SIDE_{s}": ("P{SIDE}AURICULARIS",), "HEAD_REAR": ("PBACKOFHEAD",),
})

_LANDMARK_GROUPS = _groups_sided({
    "pelvis": (("ASIS_l", "ASIS_r"), (("PSIS_l", "PSIS_r"), ("SACRUM",))),
    "leg_{s}": (("KNEE_LAT_{s}", "ANKLE_LAT_{s}"),
                (("THIGH_{s}", "SHANK_{s}", "TOE_{s}"), ("KNEE_MED_{s}", "ANKLE_MED_{s}", "TOE_{s}"),
                 ("KNEE_MED_{s}", "ANKLE_MED_{s}", "MT1_{s}", "MT5_{s}"),
                 ("THIGH_{s}", "SHANK_{s}", "MT1_{s}", "MT5_{s}"))),
    "trunk": (("C7", "IJ"), ()),
    # Four head-band markers, or a marker on each side of the head and one on the forehead
    # (or the back of the head).
    "head": ((), (("HEAD_FRONT_l", "HEAD_FRONT_r", "HEAD_BACK_l", "HEAD_BACK_r"),
                  ("HEAD_SIDE_l", "HEAD_SIDE_r", "FOREHEAD"), ("HEAD_SIDE_l", "HEAD_SIDE_r", "HEAD_REAR"))),
    # An arm needs shoulder, elbow and wrist landmarks; UPA and the medial epicondyle only
    # refine the elbow (without them the flexion axis comes from the arm's own plane).
    # The acromion may be marked by a pair either side of it (MoSh's SehoonVSK layout: front and
    # back shoulder, LFSH/LBSH), which stands for it at their midpoint.
    "arm_{s}": (("ELBOW_LAT_{s}",),
                tuple((*wrist, *shoulder) for shoulder in (("ACROMION_{s}",),
                                                           ("SHOULDER_FRONT_{s}", "SHOULDER_BACK_{s}"))
                      for wrist in (("WRIST_RAD_{s}", "WRIST_ULN_{s}"), ("WRIST_{s}",)))),
})

#: Roles that refine a part where they are marked, though it is computed without them: the
#: thorax axis (T10, PX), an arm's upper-arm wand, medial epicondyle and hand end.
_LANDMARK_REFINING: dict[str, tuple[str, ...]] = {
    "trunk": ("T10", "PX"),
    **{f"arm_{s}": (f"UPPER_ARM_{s}", f"ELBOW_MED_{s}", f"HAND_{s}", f"MC2_{s}", f"MC5_{s}")
       for s in "lr"},
}

_CLUSTER_GROUPS = _groups_sided({
    "pelvis": (tuple(f"PELVIS_{k}" for k in range(1, 5)), ()),
    "leg_{s}": (tuple(f"{seg}_{k}_{{s}}" for seg, n in (("THIGH", 4), ("SHANK", 4), ("FOOT", 3))
                      for k in range(1, n + 1)), ()),
})

PRESETS: dict[str, MarkerSet] = {
    m.name: m for m in [
        MarkerSet("plug_in_gait", "Vicon Plug-in Gait, full or lower body (LASI, LKNE, LTHI, "
                  "LANK, LTIB, LTOE, C7, CLAV, LSHO, LELB, LWRA, LFHD, ...)",
                  _PIG_ROLES, _LANDMARK_GROUPS,
                  ("ASIS_l", "ASIS_r", "KNEE_LAT_l", "ANKLE_LAT_l", "TOE_l"),
                  refining=_LANDMARK_REFINING),
        MarkerSet("plug_in_gait_lower", "Vicon Plug-in Gait lower body (pelvis and legs only; "
                  "upper-body markers are ignored)",
                  _PIG_ROLES, {g: v for g, v in _LANDMARK_GROUPS.items()
                               if g in ("pelvis", "leg_l", "leg_r")},
                  ("ASIS_l", "ASIS_r", "KNEE_LAT_l", "ANKLE_LAT_l", "TOE_l")),
        MarkerSet("helen_hayes", "Helen Hayes / Davis (Kadaba 1990, Davis 1991) as Cortex, BTS "
                  "and Codamotion write it (ASIS, SACR/VSAC, THI/bar 1, KNE/knee 1, TIB/SHA/bar 2, "
                  "ANK/mall, TOE/met, SHO, ELB, WRI)",
                  _HH_ROLES, _LANDMARK_GROUPS,
                  ("ASIS_l", "ASIS_r", "KNEE_LAT_l", "ANKLE_LAT_l", "TOE_l"),
                  refining=_LANDMARK_REFINING),
        MarkerSet("isb_anatomical", "anatomical landmarks, ISB/CAST names (ASIS, PSIS, FLE/FME, "
                  "FAL/TAM, FM1/FM5, AC, HLE/HME, RSP/USP, IJ, PX, C7)",
                  _ISB_ROLES, _LANDMARK_GROUPS,
                  ("ASIS_l", "ASIS_r", "KNEE_LAT_l", "KNEE_MED_l", "ANKLE_LAT_l", "ANKLE_MED_l"),
                  refining=_LANDMARK_REFINING),
        MarkerSet("xsens_mvn", "Xsens MVN virtual anatomical markers (pLeftASI, pSacrum, "
                  "pLeftKneeLatEpicondyle, pLeftLatMalleolus, pLeftFirstMetatarsal, pIJ, "
                  "pC7SpinalProcess, pLeftAcromion, pLeftArmLatEpicondyle, pLeftRadialStyloid, ...)",
                  _XSENS_ROLES, _LANDMARK_GROUPS,
                  ("ASIS_l", "ASIS_r", "KNEE_LAT_l", "KNEE_MED_l", "ANKLE_LAT_l", "ANKLE_MED_l"),
                  refining=_LANDMARK_REFINING),
        MarkerSet("animation", "animation sets, markers near the landmarks (OptiTrack Motive "
                  "Baseline, Qualisys Animation: WaistLFront, LKneeOut, LAnkleOut, LToeOut, "
                  "BackTop, Chest, LShoulderTop, LElbowOut, LWristOut, HeadL, ...): joint "
                  "centres approximate",
                  _ANIMATION_ROLES, _LANDMARK_GROUPS,
                  ("ASIS_l", "ASIS_r", "KNEE_LAT_l", "ANKLE_LAT_l", "MT5_l"),
                  refining=_LANDMARK_REFINING),
        MarkerSet("cluster_gait", "technical clusters, pelvis and legs (PV1-4, RTH1-4, RSK1-4, "
                  "RFT1-3; c3d.org Eb015pi): functional joint centres",
                  _CLUSTER_ROLES, _CLUSTER_GROUPS,
                  ("PELVIS_1", "PELVIS_2", "PELVIS_3", "THIGH_1_l", "SHANK_1_l", "FOOT_1_l"),
                  method="functional"),
    ]
}


@dataclass
class MarkerMap:
    """The result of matching a file's labels to a marker set.

    marker : role -> index into the file's markers (only roles that were found).
    subject : the subject prefix used ('' when none); ignored : labels of other objects.
    how : a sentence for the import report.
    """

    preset: MarkerSet
    marker: dict[str, int]
    subject: str
    ignored: list[str] = field(default_factory=list)
    how: str = ""
    #: body part -> why it could not be computed (set by :func:`check_usable`).
    not_computed: dict[str, str] = field(default_factory=dict)
    #: role -> every usable marker of the subject with the role's label (only roles whose label
    #: names several markers, e.g. Cortex's ``RKNE`` for both femoral epicondyles).
    same_label: dict[str, list[int]] = field(default_factory=dict)
    #: index -> label key without the subject's prefix, for every label of the subject.
    keys: dict[int, str] = field(default_factory=dict)
    #: role -> the label naming it that holds no sample in the trial (the role is missing).
    unseen: dict[str, str] = field(default_factory=dict)


#: The suffix some software appends to a duplicated label (``LASI_1``, ``LASI_2``): such a
#: label stands for the label itself where no marker of the role is in the file with a sample.
#: Only with an underscore: ``RKD1``, ``PV1``, ``r knee 2`` are markers of their own.
_DUPLICATE_SUFFIX = re.compile(r"_\d+$")


def _resolve(preset: MarkerSet, names: dict[int, str], usable: set[int]) -> dict[str, int]:
    """role -> marker index. Per role, the candidates' exact labels in candidate order, then
    duplicate-suffixed ones (:data:`_DUPLICATE_SUFFIX`); the first that holds samples wins,
    else the first (reported as never seen)."""
    every = {c for cands in preset.roles.values() for c in cands}
    exact: dict[str, list[int]] = {}
    duplicate: dict[str, list[int]] = {}
    for i, name in names.items():
        key = label_key(name)
        exact.setdefault(key, []).append(i)
        base = _DUPLICATE_SUFFIX.sub("", name)
        if base != name and key not in every:
            duplicate.setdefault(label_key(base), []).append(i)
    found = {}
    for role, cands in preset.roles.items():
        options = [i for table in (exact, duplicate) for c in cands for i in table.get(c, [])]
        if options:
            found[role] = min(options, key=lambda i: i not in usable)
    return found


#: A prefix ending at ``_`` or a space that this many of a subject's labels share is tried as
#: the subject's name too (``Jo_LASI``, ``Jo LASI``, ``Subject_001_LASI``): the reading that
#: finds more roles wins, so a side or role word (``L_IAS``, ``r asis``) is kept.
MIN_PREFIXED = MIN_ROLES_DETECTED
_PREFIX_END = re.compile(r"[\s_]+(?=\S)")


def _subjects(labels: list[str]) -> dict[str, dict[int, str]]:
    """subject -> {index: label without the subject's prefix}: the ``Bob:`` prefixes (``''``
    for labels without one), then each shared prefix before ``_`` or a space
    (:data:`MIN_PREFIXED`)."""
    out: dict[str, dict[int, str]] = {}
    for i, lab in enumerate(labels):
        out.setdefault(subject_of(lab), {})[i] = lab.split(":")[-1].strip()
    for subject, names in list(out.items()):
        prefixed: dict[str, dict[int, str]] = {}
        for i, name in names.items():
            for end in _PREFIX_END.finditer(name):
                prefixed.setdefault(name[:end.start()], {})[i] = name[end.end():]
        for prefix, rest in prefixed.items():
            if len(rest) >= MIN_PREFIXED:
                out.setdefault(f"{subject}:{prefix}" if subject else prefix, rest)
    return out


def match_markers(labels: list[str], spec: str | None = None,
                  usable: list[bool] | None = None) -> MarkerMap:
    """Match ``labels`` to a marker set. ``spec``: None (detect), a preset name or a YAML map.

    With several subject prefixes in the file, the subject whose labels match a preset best is
    used and the others' markers are ignored. ``usable``: per label, whether it holds samples;
    of a role's markers (same label or key, synonyms, duplicates) the first usable one is
    taken (:func:`_resolve`). Raises
    :class:`MappingError`.
    """
    user: dict[str, str] = {}
    user_lines: dict[str, int] = {}
    user_path: str | None = None
    base: str | None = None
    subject_wanted: str | None = None
    if spec is not None:
        if spec in PRESETS:
            base = spec
        elif spec.endswith((".yaml", ".yml")) or Path(spec).exists():
            user_path = spec
            base, subject_wanted, user, user_lines = load_marker_map(spec)
        else:
            hint = did_you_mean(spec, PRESETS, parenthesized=True)
            raise MappingError(f"--map {quoted(spec)}: not a marker-set preset nor a YAML file{hint}; "
                               f"marker sets: {', '.join(PRESETS)}")
    best: tuple[int, str, MarkerSet, dict[str, int]] | None = None
    subjects = _subjects(labels)
    with_samples = {i for i in range(len(labels)) if usable is None or usable[i]}
    for subject, names in subjects.items():
        if subject_wanted is not None and subject != subject_wanted:
            continue
        candidates = [PRESETS[base]] if base else list(PRESETS.values())
        for preset in candidates:
            found = _resolve(preset, names, with_samples)
            # Detected when most of its signature (lower body) is there, or many of its roles
            # (an upper-body trial); what is missing is then listed per body part.
            if not base and 2 * sum(r in found for r in preset.signature) <= len(preset.signature) \
                    and len(found) < MIN_ROLES_DETECTED:
                continue
            if best is None or len(found) > best[0]:
                best = (len(found), subject, preset, found)
    if best is None:
        if subject_wanted is not None and subject_wanted not in subjects:
            raise MappingError(f"no markers of subject {quoted(subject_wanted)}; subjects in the "
                               f"file: {listed(quoted(s) for s in dict.fromkeys(map(subject_of, labels)))}")
        raise MappingError(
            f"no marker set recognised from the labels ({listed(quoted(lab) for lab in labels)}); "
            f"give --map PRESET (presets: {', '.join(PRESETS)}) or FILE.yaml "
            "(markers: {ROLE: label})")
    _, subject, preset, found = best
    keys = {i: label_key(name) for i, name in subjects[subject].items()}
    how = f"marker set {preset.name} ({'requested' if base and not user_path else 'detected'})"
    if user_path:
        how = f"marker set {preset.name} + {user_path}"
    for role, label in user.items():
        if role not in preset.roles:
            hint = did_you_mean(role, preset.roles, parenthesized=True)
            raise InputError(user_path, f"markers.{role}: unknown role for {preset.name}{hint}; "
                                        f"roles: {listed(preset.roles)} (all in "
                                        "docs/import.md#marker-maps)", user_lines[role])
        matches = [i for i, k in keys.items()
                   if label_key(label) in (k, label_key(labels[i].split(":")[-1]))]
        if not matches:
            close = difflib.get_close_matches(label, labels, n=3)
            raise InputError(user_path, f"markers.{role}: no marker {quoted(label)} in the file "
                                        f"(closest: {listed(quoted(c) for c in close) or 'none'})",
                             user_lines[role])
        found[role] = matches[0]
    if subject:
        how += f", subject {subject!r}"
    ignored = [lab for i, lab in enumerate(labels) if i not in keys]
    same_label = {role: same for role, i in found.items()
                  if len(same := [j for j in keys if j in with_samples and keys[j] == keys[i]]) > 1}
    return MarkerMap(preset, found, subject, ignored, how, same_label=same_label, keys=keys)


def part_roles(preset: MarkerSet, group: str) -> tuple[str, ...]:
    """Every role that places body part ``group``: required, alternatives and refining."""
    required, alternatives = preset.groups[group]
    return tuple(dict.fromkeys([*required, *(r for alt in alternatives for r in alt),
                                *preset.refining.get(group, ())]))


def group_status(mmap: MarkerMap) -> tuple[list[str], list[str], dict[str, list[str]]]:
    """Which body parts are present, absent, or incomplete.

    Returns (present groups, absent groups, incomplete: group -> missing marker descriptions).
    A group is absent when none of its markers is in the file.
    """
    present, absent, incomplete = [], [], {}
    preset = mmap.preset
    for group, (required, alternatives) in preset.groups.items():
        roles = set(required) | {r for alt in alternatives for r in alt}
        if not any(r in mmap.marker for r in roles):
            absent.append(group)
            continue
        missing = [_describe(mmap, r) for r in required if r not in mmap.marker]
        if alternatives and not any(all(r in mmap.marker for r in alt) for alt in alternatives):
            # The ways this preset can mark (the groups are shared: Plug-in Gait has no head side
            # markers), each said once, and none that lacks more than a shorter way does.
            markable = [alt for alt in alternatives if all(r in preset.roles for r in alt)]
            lacking = [tuple(r for r in alt if r not in mmap.marker) for alt in markable or alternatives]
            shortest = [alt for alt in dict.fromkeys(lacking)
                        if not any(set(other) < set(alt) for other in lacking)]
            missing.append(" or ".join("+".join(_describe(mmap, r) for r in alt) for alt in shortest))
        if missing:
            incomplete[group] = missing
        else:
            present.append(group)
    return present, absent, incomplete


def _describe(mmap: MarkerMap, role: str) -> str:
    """A missing role as the message names it: its label with no sample, or its first candidate."""
    if role in mmap.unseen:
        return f"{mmap.unseen[role]} (no sample)"
    cands = mmap.preset.roles.get(role, ())
    return cands[0] if cands else role


#: A body part that cannot be computed is reported in one message of at most this many characters.
MESSAGE_MAX = 300


def _part_message(mmap: MarkerMap, labels: list[str], group: str, missing: list[str],
                  why: str = "") -> str:
    """``left arm not computed: found LSHO; lacks LELB, LWRA+LWRB or LWRI`` (< 300 chars)."""
    required, alternatives = mmap.preset.groups[group]
    roles = list(dict.fromkeys([*required, *(r for alt in alternatives for r in alt)]))
    found = [labels[mmap.marker[r]] for r in roles if r in mmap.marker]
    text = (f"{GROUP_WORDS[group]} not computed{why}: found {listed(found, 4) if found else 'none'}"
            f"; lacks {listed(missing, 3) if missing else 'nothing'}")
    return text if len(text) < MESSAGE_MAX else text[:MESSAGE_MAX - 4] + " ..."


def check_usable(mmap: MarkerMap, labels: list[str]) -> tuple[list[str], list[str]]:
    """(present, absent) groups; every body part whose markers are all there is computed.

    A part with only some of its markers is marked absent too, and ``mmap.not_computed`` holds
    one message per such part (the part, the markers found, the ones it lacks). The legs hang
    from the pelvis, so they are absent when the pelvis is. Raises :class:`MappingError` only
    when nothing can carry the body: neither the pelvis nor (an upper-body trial) the trunk.
    """
    present, _absent, incomplete = group_status(mmap)
    notes: dict[str, str] = {g: _part_message(mmap, labels, g, m) for g, m in incomplete.items()}
    if "pelvis" not in present:
        for s in "lr":
            if f"leg_{s}" in present:
                present.remove(f"leg_{s}")
                notes[f"leg_{s}"] = _part_message(mmap, labels, f"leg_{s}", [],
                                                  " (no pelvis to hang it from)")
    functional = mmap.preset.method == "functional"
    if functional and incomplete:
        raise MappingError(f"{mmap.how}: " + "; ".join(notes.values())[:MESSAGE_MAX])
    if "pelvis" not in present and ("trunk" not in present or functional):
        pelvis = notes.get("pelvis") or _part_message(
            mmap, labels, "pelvis", [_describe(mmap, r) for r in mmap.preset.groups["pelvis"][0]])
        trunk = notes.get("trunk", "")
        raise MappingError(f"{mmap.how}: nothing to carry the body: {pelvis}"
                           + (f"; {trunk}" if trunk and not functional else "")
                           + " (name the markers with --map FILE.yaml)")
    mmap.not_computed = {g: notes[g] for g in GROUPS if g in notes}
    return present, [g for g in GROUPS if g not in present]


def load_marker_map(path: str | Path) -> tuple[str | None, str | None, dict[str, str], dict[str, int]]:
    """A user marker map: ``{base: PRESET, subject: NAME, markers: {ROLE: label}}`` (all optional
    but ``markers`` or ``base``). Returns (base, subject, markers, line of each marker entry)."""
    path = str(path)
    node = compose_yaml(path, "map")
    if node is None or not isinstance(node, yaml.MappingNode):
        raise InputError(path, "a marker map must be a mapping with 'markers:' (and optional "
                               "'base:', 'subject:')", 1)
    base: str | None = None
    subject: str | None = None
    markers: dict[str, str] = {}
    lines: dict[str, int] = {}
    for key_node, value_node in node.value:
        key, line = key_node.value, key_node.start_mark.line + 1
        if key == "base":
            base = str(value_node.value)
            if base not in PRESETS:
                raise InputError(path, f"base: unknown marker set {quoted(base)}; marker sets are "
                                       f"{', '.join(PRESETS)}", line)
        elif key == "subject":
            subject = str(value_node.value)
        elif key == "markers":
            if not isinstance(value_node, yaml.MappingNode):
                raise InputError(path, "markers: expected a mapping ROLE: label", line)
            for k_node, v_node in value_node.value:
                if not isinstance(v_node, yaml.ScalarNode) or not v_node.value:
                    raise InputError(path, f"markers.{k_node.value}: expected a marker label",
                                     k_node.start_mark.line + 1)
                markers[str(k_node.value)] = str(v_node.value)
                lines[str(k_node.value)] = k_node.start_mark.line + 1
        else:
            hint = did_you_mean(str(key), ["base", "subject", "markers"], parenthesized=True)
            raise InputError(path, f"{key}: unknown key{hint}; expected 'base', 'subject', "
                                   "'markers'", line)
    if base is None:
        base = "plug_in_gait"
    return base, subject, markers, lines


def preset_summary() -> str:
    return "\n".join(f"  {p.name:18s} {p.description}" for p in PRESETS.values())
