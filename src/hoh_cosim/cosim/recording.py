"""A run's record: every output of every component at every tick, whichever engine stepped it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hoh_cosim.cosim.scenario import ComponentSpec

__all__ = ["Recording", "recording_layout"]


@dataclass
class Recording:
    """Every output of every component at every tick, and how long the run took."""

    time: np.ndarray  # (n + 1,)
    values: np.ndarray  # (n + 1, total outputs)
    columns: dict[str, slice]  # "component.port" -> columns
    element_names: dict[str, list[str]]  # "component.port" -> its CSV column names
    wall_s: float
    engine: str
    coupling: str = "gauss-seidel"  # our master's; "jacobi" (libcosim), "jacobi-eager" (ecos)

    def __getitem__(self, signal: str) -> np.ndarray:
        """`component.port` as an (n + 1, size) array."""
        return self.values[:, self.columns[signal]]

    def __contains__(self, signal: str) -> bool:
        return signal in self.columns


def recording_layout(
    components: Sequence[ComponentSpec],
) -> tuple[dict[str, slice], dict[str, list[str]]]:
    """The columns of a `Recording`: every output port of every component, in order."""
    columns: dict[str, slice] = {}
    names: dict[str, list[str]] = {}
    offset = 0
    for c in components:
        for port in c.outputs:
            key = f"{c.name}.{port.name}"
            columns[key] = slice(offset, offset + port.size)
            names[key] = [f"{c.name}.{n}" for n in port.element_names]
            offset += port.size
    return columns, names
