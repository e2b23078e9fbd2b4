"""The hip as the lab's gait model places it from the leg length the file stores: Davis et al.
1991 (Plug-in Gait, BTS) or Hara et al. 2016 (pyCGM2's CGM 2.1 and later)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


#: Davis et al. 1991 (Hum Mov Sci 10:575): the hip lies C = 0.115 L - 15.3 mm (L the leg
#: length, the mean of both legs as Plug-in Gait takes it) from the ASIS along a line at THETA to
#: the frontal plane and BETA to the transverse one (0.5 and 0.314 rad, the values Plug-in Gait
#: and pyCGM use), set back by the ASIS-trochanter distance plus a marker radius. Without a
#: measured distance the model takes 0.1288 L - 48.56 mm, which Plug-in Gait writes back to the
#: file.
DAVIS_C_PER_LEG, DAVIS_C_M = 0.115, -0.0153


DAVIS_THETA_RAD, DAVIS_BETA_RAD = 0.5, 0.314


DAVIS_TROCHANTER_PER_LEG, DAVIS_TROCHANTER_M = 0.1288, -0.04856


#: Hara et al. 2016 (Sci Rep 6:37707), in the pelvis frame from the mid-ASIS: (forward, lateral,
#: up) = HARA_PER_LEG * L + HARA_M (L the leg length). pyCGM2 moves it back by the marker radius
#: and a 2 mm base plate (its markers sit on the skin, the regression's on the bone).
HARA_PER_LEG = np.array([-0.063, 0.086, -0.078])


HARA_M = np.array([0.011, 0.008, -0.009])


HARA_BASE_PLATE_M = 0.002


def lab_model_hip(anthropometry: dict[str, float], lab_model: str, side: str,
                  marker_radius_m: float, asis_width_m: float) -> tuple[F64, str] | None:
    """The hip of ``side`` in the pelvis frame (x forward, y the lateral distance, z up; from
    the mid-ASIS; (3,) metres) as the lab's model placed it from the subject's leg length the
    file stores, with how it was placed; None where the file stores no leg length.

    A file that stores a leg length was processed by a lab's model, whose centres it often holds
    too: pyCGM2's CGM 2.1 and later (``lab_model``) place the hips by Hara 2016; Plug-in Gait
    (and BTS's Davis protocol) by Davis 1991 with the file's ASIS-trochanter distance, measured or
    the model's own regression on the leg, and the inter-ASIS distance (else the markers',
    ``asis_width_m``). Measured on the files here that store centres: Hara puts ours 4-5 mm from
    a CGM 2.4 file's (Harrington from the markers: 20-25 mm), Davis with a measured trochanter
    distance 6-13 mm from BTS's (Harrington: 21-26 mm). Davis on its regressed distance is
    unmeasured against a lab's centres (on the CGM 2.4 file, its model's name removed: 19 mm);
    a CGM 2.x file that does not name its model gets Davis."""
    leg = anthropometry.get(f"leg_length_{side}")
    if leg is None:
        return None
    if lab_model.startswith("CGM 2."):
        local = HARA_PER_LEG * leg + HARA_M
        local[0] -= marker_radius_m + HARA_BASE_PLATE_M
        return local, (f"Hara 2016 with the file's leg length {leg * 1000:.0f} mm ({lab_model}, "
                       "as the file says)")
    trochanter = anthropometry.get(f"asis_trochanter_{side}",
                                   DAVIS_TROCHANTER_PER_LEG * leg + DAVIS_TROCHANTER_M)
    asis = anthropometry.get("asis_distance", asis_width_m)
    both_legs = [anthropometry[k] for k in ("leg_length_l", "leg_length_r") if k in anthropometry]
    c = DAVIS_C_PER_LEG * float(np.mean(both_legs)) + DAVIS_C_M
    theta, beta = DAVIS_THETA_RAD, DAVIS_BETA_RAD
    back = trochanter + marker_radius_m
    local = np.array([c * math.cos(theta) * math.sin(beta) - back * math.cos(beta),
                      0.5 * asis - c * math.sin(theta),
                      -c * math.cos(theta) * math.cos(beta) - back * math.sin(beta)])
    return local, (f"Davis 1991 with the file's leg length {leg * 1000:.0f} mm, ASIS-trochanter "
                   f"distance {trochanter * 1000:.0f} mm and ASIS distance {asis * 1000:.0f} mm")
