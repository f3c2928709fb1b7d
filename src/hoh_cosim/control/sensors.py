"""The names of the sensors a session may read, in a module of its own: the command line's parser
offers them without loading the control cycle."""

from __future__ import annotations

__all__ = ["PROBE_SENSORS"]

PROBE_SENSORS = ("fse103", "loadcell", "none")
"""The probe sensors a scenario (`probe_sensor`) and a rig (`probe.sensor`, `--probe-sensor`) may
name: the Variense FSE103, the Honeywell Model 31 load cell, or none."""
