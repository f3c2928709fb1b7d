"""Writes tests/data/poses_seed_tool.csv: 32 synthetic static poses of the seed's tool.

    python tests/data/make_poses.py

The seed's identified tool (mg = 4.7631 N, p_COM = (-0.01250, -0.00033, 0) m, section 4.B) with a
sensor offset, seen from the 32 tilted poses of `tests.poses.seed_like_poses`, each reading the mean of
1000 samples with the seed's noise (seed 000, sections 3.D and 4.C). Random seed 32.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from hoh_cosim.control.frames import matrix_to_rotvec  # noqa: E402
from hoh_cosim.control.gravity import SEED_TOOL  # noqa: E402
from tests.poses import seed_like_poses, synthetic_readings  # noqa: E402

OUT = Path(__file__).with_name("poses_seed_tool.csv")


def make() -> str:
    R_BS = seed_like_poses()
    wrench = synthetic_readings(R_BS, SEED_TOOL, np.random.default_rng(32))
    lines = ["rx,ry,rz,fx,fy,fz,tx,ty,tz"]
    for R, w in zip(R_BS, wrench, strict=True):
        lines.append(",".join(f"{x:.9f}" for x in (*matrix_to_rotvec(R), *w)))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    OUT.write_text(make())
    print(f"wrote {OUT}")
