"""The gravity-calibration drive: through N static poses, holding still at each (seed 000, 3.D).

The seed's batch script moved the robot through 32 known static poses and averaged 1000 F/T samples
at each. This block does the moving with speedL twists: for each pose it servos the TCP to the target
orientation (the start orientation tilted about a horizontal axis) at the start position, then stops,
waits for the arm and the sensor to settle, and holds still while the caller averages the readings
(`holding` is 1 then).

Poses: `tilts` tilts (15, 30, 45, 60 degrees by default) in each of `directions` horizontal directions
(4 x 8 = 32 by default, the seed's number). The schedule starts at the block's first step. The servo
is proportional with speed limits: v = k_p (p* - p), ω = k_r log(R* Rᵀ).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.block import TWIST_UNITS, Port
from hoh_cosim.control.frames import matrix_to_rotvec, rotvec_to_matrix
from hoh_cosim.control.limits import clamp_speed
from hoh_cosim.control.vectors import Rot3, Vec, as_scalar
from hoh_cosim.errors import ConfigError

__all__ = ["PoseSequencer", "SequencerParams", "servo_twist", "tilted_orientations"]


@dataclass(frozen=True)
class SequencerParams:
    tilts: int = 4  # tilts evenly spaced from tilt_min_deg to tilt_max_deg (one: tilt_max_deg)
    tilt_min_deg: float = 15.0
    tilt_max_deg: float = 60.0
    directions: int = 8
    move_s: float = 3.0  # [s] allowed for each move
    settle_s: float = 0.5  # [s] still, before averaging
    hold_s: float = 5.0  # [s] averaging: 1000 FT-150 packets at 200 Hz (the seed's count)
    gain_position: float = 3.0  # [1/s]
    gain_orientation: float = 3.0  # [1/s]
    max_linear_speed: float = 0.05  # [m/s]
    max_angular_speed: float = 0.5  # [rad/s]

    UNITS: ClassVar[dict[str, Any]] = {
        "tilts": "1",
        "tilt_min_deg": "deg",
        "tilt_max_deg": "deg",
        "directions": "1",
        "move_s": "s",
        "settle_s": "s",
        "hold_s": "s",
        "gain_position": "1/s",
        "gain_orientation": "1/s",
        "max_linear_speed": "m/s",
        "max_angular_speed": "rad/s",
    }

    def __post_init__(self) -> None:
        for name in ("tilts", "directions"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("tilt_min_deg", "tilt_max_deg"):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, high=120.0)
            )
        if self.tilt_min_deg > self.tilt_max_deg:
            raise ConfigError(
                f"tilt_min_deg must be <= tilt_max_deg ({self.tilt_max_deg}), "
                f"got {self.tilt_min_deg}"
            )
        for name in (
            "move_s",
            "hold_s",
            "gain_position",
            "gain_orientation",
            "max_linear_speed",
            "max_angular_speed",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(self, "settle_s", as_scalar(self.settle_s, "settle_s", low=0.0))

    @property
    def tilts_deg(self) -> tuple[float, ...]:
        """The tilts, from the smallest: 15, 30, 45, 60 by default (the seed's)."""
        if self.tilts == 1:
            return (self.tilt_max_deg,)
        return tuple(
            float(x) for x in np.linspace(self.tilt_min_deg, self.tilt_max_deg, self.tilts)
        )

    @property
    def n_poses(self) -> int:
        return len(self.tilts_deg) * self.directions

    @property
    def pose_s(self) -> float:
        """Time spent on each pose: move, settle, hold."""
        return self.move_s + self.settle_s + self.hold_s


def tilted_orientations(R_start: Rot3, params: SequencerParams) -> list[Rot3]:
    """R_start tilted by each tilt about horizontal axes in `directions` directions (base frame)."""
    out = []
    for tilt in params.tilts_deg:
        for k in range(params.directions):
            azimuth = 2.0 * math.pi * k / params.directions
            axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
            out.append(rotvec_to_matrix(math.radians(tilt) * axis) @ R_start)
    return out


def servo_twist(
    p_target: Vec, R_target: Rot3, p_now: Vec, R_now: Rot3, params: SequencerParams
) -> Vec:
    """The speedL twist towards a pose: v = k_p (p* - p), ω = k_r log(R* Rᵀ), each speed-limited."""
    v = params.gain_position * (p_target - p_now)
    w = params.gain_orientation * matrix_to_rotvec(R_target @ R_now.T)
    v, _ = clamp_speed(v, params.max_linear_speed)
    w, _ = clamp_speed(w, params.max_angular_speed)
    return np.concatenate([v, w])


class PoseSequencer:
    """Servo through the calibration poses under the block contract."""

    inputs: ClassVar[tuple[Port, ...]] = (
        Port("p_BT_B", 3, "m", "TCP position in the base frame"),
        Port("R_BT", 9, "1", "TCP orientation in the base frame, row by row"),
    )
    outputs: ClassVar[tuple[Port, ...]] = (
        Port("twist_B", 6, TWIST_UNITS, "speedL command [v; ω] in the base frame"),
        Port("pose_index", 1, "1", "the pose being visited, from 1"),
        Port("holding", 1, "1", "1 while the robot holds still for averaging, else 0"),
        Port("done", 1, "1", "1 once every pose has been held"),
    )

    def __init__(self, params: SequencerParams | None = None) -> None:
        self.params = params or SequencerParams()
        self.reset()

    def reset(self) -> None:
        self._start: tuple[Vec, Rot3] | None = None
        self._t0 = 0.0
        self._targets: list[Rot3] = []

    def step(self, t: float, dt: float, inputs: Mapping[str, Vec]) -> dict[str, Vec]:
        p = self.params
        p_now, R_now = inputs["p_BT_B"], inputs["R_BT"].reshape(3, 3)
        if self._start is None:  # the schedule starts at the first step
            self._start = (p_now.copy(), R_now.copy())
            self._t0 = t
            self._targets = tilted_orientations(R_now, p)
        elapsed = t + dt - self._t0
        index = int(elapsed // p.pose_s)
        if index >= len(self._targets):
            return self._out(np.zeros(6), len(self._targets), holding=False, done=True)
        phase = elapsed - index * p.pose_s
        if phase >= p.move_s:  # settle, then hold: stand still
            return self._out(
                np.zeros(6), index + 1, holding=phase >= p.move_s + p.settle_s, done=False
            )
        twist = servo_twist(self._start[0], self._targets[index], p_now, R_now, p)
        return self._out(twist, index + 1, holding=False, done=False)

    @staticmethod
    def _out(twist: Vec, index: int, holding: bool, done: bool) -> dict[str, Vec]:
        return {
            "twist_B": twist,
            "pose_index": np.array([float(index)]),
            "holding": np.array([1.0 if holding else 0.0]),
            "done": np.array([1.0 if done else 0.0]),
        }
