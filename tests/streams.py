"""Packet streams for driving the estimator in tests: what the two sensors would send.

The wrist sensor reads hand + contact + tool weight + offset (+ noise) in S, a packet every
`ft_every` ticks; the probe sensor reads the contact force in P every `probe_every` ticks. Counters
start at 1 with the first packet.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from hoh_cosim.control.frames import R_BS_EQ1, R_SP_SEED
from hoh_cosim.control.gravity import SEED_TOOL, ToolParams, tool_weight_wrench_S

Zero3 = lambda t: np.zeros(3)  # noqa: E731


@dataclass
class SensorStream:
    R_BS: Callable[[float], np.ndarray] = lambda t: R_BS_EQ1
    hand_B: Callable[[float], np.ndarray] = Zero3  # force of the hand on the tool, in B
    hand_torque_B: Callable[[float], np.ndarray] = Zero3
    contact_B: Callable[[float], np.ndarray] = Zero3  # force of the patient on the probe, in B
    tool: ToolParams = SEED_TOOL
    ft_bias: np.ndarray = field(
        default_factory=lambda: np.array([1.0, -2.0, 0.5, 0.02, -0.01, 0.03])
    )
    probe_bias: np.ndarray = field(default_factory=lambda: np.array([0.3, 0.1, -0.2]))
    ft_sigma: np.ndarray = field(default_factory=lambda: np.zeros(6))
    probe_sigma: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ft_every: int = 5
    probe_every: int = 20
    dt: float = 1e-3
    seed: int = 0

    def ticks(self, n: int) -> Iterator[tuple[float, dict[str, np.ndarray]]]:
        rng = np.random.default_rng(self.seed)
        ft_count = probe_count = 0
        inputs = {
            "wrench_S": np.zeros(6),
            "ft_counter": np.zeros(1),
            "force_P": np.zeros(3),
            "probe_counter": np.zeros(1),
            "R_BS": np.eye(3).reshape(9),
        }
        for k in range(n):
            t = k * self.dt
            R_BS = self.R_BS(t)
            inputs["R_BS"] = R_BS.reshape(9).copy()
            if k % self.ft_every == 0:
                ft_count += 1
                F_ext_S = R_BS.T @ (self.hand_B(t) + self.contact_B(t))
                tau_S = R_BS.T @ self.hand_torque_B(t)
                w = tool_weight_wrench_S(R_BS, self.tool) + self.ft_bias
                w = w + np.concatenate([F_ext_S, tau_S]) + rng.normal(0.0, 1.0, 6) * self.ft_sigma
                inputs["wrench_S"] = w
                inputs["ft_counter"] = np.array([float(ft_count)])
            if k % self.probe_every == 0:
                probe_count += 1
                R_BP = R_BS @ R_SP_SEED
                f = R_BP.T @ self.contact_B(t) + self.probe_bias
                inputs["force_P"] = f + rng.normal(0.0, 1.0, 3) * self.probe_sigma
                inputs["probe_counter"] = np.array([float(probe_count)])
            yield t, {name: value.copy() for name, value in inputs.items()}
