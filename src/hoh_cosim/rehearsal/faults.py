"""The faults a rehearsal world can inject: a closed set, in a module light enough for a command line.

Each happens at a time of the rehearsal world's clock (`Fault.at_s`) or when a campaign injects it
(`RehearsalWorld.inject`), and lasts `duration_s` where a duration means something (0: for good):

    probe_unplug     the FSE103's pty closes
    probe_garbage    junk bytes in the FSE103's stream
    probe_framing    the FSE103 switches to the other framing (as a device reset to another
                     output mode would)
    force_spike      40 N more on the probe sensor
    ft_stall         the FT-150 stream stays open and goes quiet
    ft_garbage       junk bytes in the FT-150 stream
    ft_nan           FT-150 samples of NaNs (one sample when the duration is 0)
    ft_spike         60 N more along the FT-150's z axis, as a knock on the handle
    ft_disconnect    the FT-150 daemon closes the connection and accepts none, then accepts again
    protective_stop  the robot's protective stop
"""

from __future__ import annotations

from dataclasses import dataclass

from hoh_cosim.errors import ConfigError

__all__ = ["CAMPAIGN_KINDS", "FAULTS", "Fault"]

FAULTS = (
    "probe_unplug",
    "probe_garbage",
    "probe_framing",
    "force_spike",
    "ft_stall",
    "ft_garbage",
    "ft_nan",
    "ft_spike",
    "ft_disconnect",
    "protective_stop",
)

CAMPAIGN_KINDS = (
    "ft_stall",
    "ft_garbage",
    "ft_nan",
    "ft_spike",
    "ft_disconnect",
    "probe_unplug",
    "probe_garbage",
    "probe_framing",
    "force_spike",
    "protective_stop",
    "emergency_stop",
    "rtde_drop",
    "program_stopped",
    "runner_kill",
    "cpu_hog",
)
"""The kinds of fault `hw campaign` draws from, in its order (a run's first fault is
CAMPAIGN_KINDS[seed % n]; `rehearsal.campaign.KINDS` says what each calls for): the world's, then
the UR controller's, the dashboard's, a killed runner and a CPU hog. Here, so that the command
line names them without importing the campaign."""


@dataclass(frozen=True)
class Fault:
    """A fault of kind `kind` at world time `at_s` [s], lasting `duration_s` [s] (0: for good)."""

    at_s: float
    kind: str
    duration_s: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in FAULTS:
            raise ConfigError(f"fault: expected one of {', '.join(FAULTS)}, got {self.kind!r}")
        if not self.duration_s >= 0.0:
            raise ConfigError(
                f"fault {self.kind}: duration: expected >= 0 s, got {self.duration_s}"
            )
