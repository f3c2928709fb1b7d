"""The SCHED_FIFO priorities of a rehearsal's processes, in a module light enough for a command line.

From the highest: the emulated devices (they stand for separate hardware, which no load on this
machine can slow), the runner's loop, the loop's helpers one below it (its readers, ur-rtde's
receivers). The kernel's own real-time threads stay above them all (99).
"""

from __future__ import annotations

__all__ = ["HARDWARE_PRIORITY", "LOOP_PRIORITY"]

HARDWARE_PRIORITY = 60
"""The emulated devices: above a runner's loop and its helpers."""

LOOP_PRIORITY = 50
"""The runner's loop unless told otherwise: a rig's loop runs at a real-time priority (the rig
file's `robot.realtime_priority`), and a rehearsal at the default priority would rehearse a loop
that any busy process on the machine can starve past the robot's watchdog."""
