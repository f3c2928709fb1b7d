"""The faults a rehearsal can inject: a closed set, in a module light enough for a command line.

Each happens at a time of the rehearsal world's clock (`Fault.at_s`):

    probe_unplug     the FSE103's pty closes
    ft_stall         the FT-150 stream stays open and goes quiet
    ft_garbage       junk bytes in the FT-150 stream
    probe_garbage    junk bytes in the FSE103's stream
    ft_nan           an FT-150 sample of NaNs
    force_spike      40 N more on the probe sensor from then on
    protective_stop  the robot's protective stop
"""

from __future__ import annotations

from dataclasses import dataclass

from hoh_cosim.errors import ConfigError

__all__ = ["FAULTS", "Fault"]

FAULTS = (
    "probe_unplug",
    "ft_stall",
    "ft_garbage",
    "probe_garbage",
    "ft_nan",
    "force_spike",
    "protective_stop",
)


@dataclass(frozen=True)
class Fault:
    """A fault of kind `kind` at world time `at_s` [s]."""

    at_s: float
    kind: str

    def __post_init__(self) -> None:
        if self.kind not in FAULTS:
            raise ConfigError(f"fault: expected one of {', '.join(FAULTS)}, got {self.kind!r}")
