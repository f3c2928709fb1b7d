"""The operator's tasks and planes: closed sets, in a module light enough for a command line.

`plant_models.operator` implements them; the rehearsal and `hw rehearse --task` offer them.
"""

from __future__ import annotations

from typing import Literal, get_args

__all__ = ["CONTACT_TASKS", "PLANES", "TASKS", "TaskName"]

TaskName = Literal[
    "off", "hold", "circle", "line", "press", "scan", "push_release", "probe_push", "view"
]
TASKS: tuple[str, ...] = get_args(TaskName)
CONTACT_TASKS = ("press", "scan", "view")  # the hand presses the probe onto the phantom
PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}
