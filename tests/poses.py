"""Static pose sets for gravity-identification tests, made the way the seed's batch script did.

The seed (section 3.D) held the tool still at 32 poses spread over the workspace and averaged 1000
F/T samples at each. `seed_like_poses` tilts the tool away from the seed's probe-down home (R_BS of
eq. 1) by four angles in eight directions; `synthetic_readings` makes the averaged readings.
"""

from __future__ import annotations

import numpy as np

from hoh_cosim.control.frames import R_BS_EQ1, rotvec_to_matrix
from hoh_cosim.control.gravity import ToolParams, tool_weight_wrench_S
from hoh_cosim.control.vectors import GRAVITY_B

SEED_NOISE_SIGMA = np.array([1.15, 1.06, 0.31, 0.0575, 0.053, 0.0155]) / 3.5
"""σ per F/T component: the seed's static max |noise| (4.C) over 3.5; torques on a 5 cm lever."""

TRUE_BIAS = np.array([1.8, -2.4, 3.1, 0.041, -0.027, 0.013])
"""A sensor offset of the size an unzeroed FT-150 shows [N, N·m]."""


def seed_like_poses(tilts_deg=(20, 45, 70, 95), directions=8) -> np.ndarray:
    """(n, 3, 3) R_BS: the home orientation tilted about horizontal axes in `directions` azimuths."""
    poses = []
    for tilt in np.radians(tilts_deg):
        for k in range(directions):
            azimuth = 2.0 * np.pi * k / directions
            axis = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
            poses.append(rotvec_to_matrix(tilt * axis) @ R_BS_EQ1)
    return np.array(poses)


def synthetic_readings(
    R_BS: np.ndarray,
    tool: ToolParams,
    rng: np.random.Generator,
    bias: np.ndarray = TRUE_BIAS,
    samples_per_pose: int = 1000,
    sigma: np.ndarray = SEED_NOISE_SIGMA,
    g_B: np.ndarray = GRAVITY_B,
) -> np.ndarray:
    """(n, 6) averaged raw readings: weight + bias + the mean of `samples_per_pose` noisy samples."""
    clean = np.array([tool_weight_wrench_S(R, tool, g_B) for R in R_BS]) + bias
    noise = rng.normal(0.0, sigma, size=(len(R_BS), samples_per_pose, 6)).mean(axis=1)
    return clean + noise
