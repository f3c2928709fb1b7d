"""One tick's estimate as the controller takes it, for tests of the controller and the supervisor."""

from __future__ import annotations

import numpy as np


def controller_inputs(**overrides: object) -> dict[str, np.ndarray]:
    """Fresh, ready, no force, the TCP at (0.3, 0, 0.3) m; any port overridden by keyword."""
    base = {
        "F_hand_B": np.zeros(3),
        "tau_hand_B": np.zeros(3),
        "F_probe_B": np.zeros(3),
        "ft_age": np.array([0.0]),
        "probe_age": np.array([0.0]),
        "ready": np.array([1.0]),
        "p_BT_B": np.array([0.3, 0.0, 0.3]),
    }
    base.update({k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in overrides.items()})
    return base
