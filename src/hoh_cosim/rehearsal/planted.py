"""Sensor faults planted in a rehearsal world for `hoh-cosim hw check --rehearse --fault NAME`.

Unlike the faults of `hoh_cosim.rehearsal.faults` (events during a session: an unplug, a spike),
these are faults a rig has from the start, the kind that cost the seed weeks (seed 000, 5.A and
3.B.2): a sensor that streams plausible numbers and is wrong. Issue 55 names them:

    ft_sign_flipped           the FT-150's Fx comes with its sign flipped (a wrong axis in a driver
                              or a mirrored mounting)
    ft_dead_channel           the FT-150's Fy reads 0 whatever the load (a broken gauge)
    ft_rate_low               the FT-150 delivers 50 Hz where the rig claims 200 Hz
    probe_frame_rotated       the FSE103 is mounted a quarter turn about the probe's axis off
                              eq. 2 (seed 3.C): what it reports is its reading turned by 90°
    fse103_nonlinear_housing  the FSE103's housing with a play of 5-6 N per axis (the seed's is
                              0.2-0.8 N, `plant_models.sensors.HousingParams`) and three times its
                              stiffening: a hysteresis the online map (`control.probe_correction`)
                              cannot model
    loadcell_saturated        the Honeywell Model 31 in constant saturation (seed 3.B.2, Fig. 9):
                              the load cell world's `saturated` parameter

A planted fault is a `Planted` record in `WorldSetup.planted` plus, for the rate, the world's own
`ft_rate_hz`; `PLANTED[name]` says which, which probe sensor the fault needs, and which sensor's
finding must name it. Faults on different channels combine (`planted_world`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.vectors import Vec
from hoh_cosim.errors import ConfigError
from plant_models.loadcell import LoadCellParams
from plant_models.sensors import HousingParams

__all__ = ["PLANTED", "Planted", "PlantedFault", "planted_world"]


@dataclass(frozen=True)
class Planted:
    """What is wrong with the world's sensors from the start (the default: nothing)."""

    ft_signs: tuple[float, ...] = (1.0,) * 6  # each FT-150 channel multiplied by its sign
    ft_dead_axis: int | None = None  # this FT-150 channel reads 0.0
    probe_rotation: tuple[float, ...] | None = None  # the FSE103's reading turned (3x3, by rows)
    housing: HousingParams | None = None  # the FSE103's housing, instead of the seed's

    def ft_values(self, values: Vec) -> Vec:
        """An FT-150 packet as the planted faults deliver it."""
        if self.ft_signs == (1.0,) * 6 and self.ft_dead_axis is None:
            return values
        out = values * np.asarray(self.ft_signs)
        if self.ft_dead_axis is not None:
            out[self.ft_dead_axis] = 0.0
        return out

    def probe_force(self, force_P: Vec) -> Vec:
        """The force the FSE103 senses, in what it takes for its frame."""
        if self.probe_rotation is None:
            return force_P
        return np.asarray(self.probe_rotation).reshape(3, 3) @ force_P

    def fse103_params(self, params: Any) -> Any:
        """The world's FSE103 parameters with the planted housing, if any."""
        return params if self.housing is None else replace(params, housing=self.housing)


_QUARTER_TURN_ABOUT_PROBE_AXIS = tuple(
    rotvec_to_matrix([0.5 * math.pi, 0.0, 0.0]).reshape(9).tolist()
)  # P's x is the probe's axis (eq. 2: x_P along z_B at home)


@dataclass(frozen=True)
class PlantedFault:
    """One fault of issue 55: the sensor whose line must fail and the finding that must name it
    (`hardware.check`), the probe sensor it needs (None: any), and what it changes in the world
    (`Planted` fields; `ft_rate_hz` the world's own; the load cell world's parameters)."""

    sensor: str
    finding: str
    needs_probe: str | None
    planted: dict[str, Any] = field(default_factory=dict)
    ft_rate_hz: float | None = None
    loadcell: dict[str, Any] = field(default_factory=dict)  # the load cell world's parameters


PLANTED: dict[str, PlantedFault] = {
    "ft_sign_flipped": PlantedFault(
        "ft150", "axis signs", None, {"ft_signs": (-1.0,) + (1.0,) * 5}
    ),
    "ft_dead_channel": PlantedFault("ft150", "noise", None, {"ft_dead_axis": 1}),
    "ft_rate_low": PlantedFault("ft150", "rate", None, ft_rate_hz=50.0),
    "probe_frame_rotated": PlantedFault(
        "fse103", "frame", "fse103", {"probe_rotation": _QUARTER_TURN_ABOUT_PROBE_AXIS}
    ),
    "fse103_nonlinear_housing": PlantedFault(
        "fse103",
        "linearity",
        "fse103",
        {"housing": HousingParams(play_N=(5.0, 6.0), stiffening=0.03)},
    ),
    "loadcell_saturated": PlantedFault(
        "loadcell", "range", "loadcell", loadcell={"saturated": True}
    ),
}


def planted_world(faults: Sequence[str], probe_sensor: str) -> tuple[Planted, dict[str, Any]]:
    """The `Planted` record and the other `WorldSetup` changes for `faults` (none: healthy); a
    fault its probe sensor cannot show is refused in one line."""
    fields: dict[str, Any] = {}
    changes: dict[str, Any] = {}
    for fault in faults:
        if fault not in PLANTED:
            raise ConfigError(f"--fault: expected one of {', '.join(PLANTED)}, got {fault!r}")
        entry = PLANTED[fault]
        if entry.needs_probe is not None and entry.needs_probe != probe_sensor:
            raise ConfigError(
                f"--fault {fault}: needs --probe-sensor {entry.needs_probe}, got {probe_sensor}"
            )
        fields.update(entry.planted)
        if entry.ft_rate_hz is not None:
            changes["ft_rate_hz"] = entry.ft_rate_hz
        if entry.loadcell:
            cell = changes.get("loadcell", LoadCellParams())
            changes["loadcell"] = replace(cell, **entry.loadcell)
    return Planted(**fields), changes
