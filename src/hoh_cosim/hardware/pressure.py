"""How starved the machine's CPU is: Linux's pressure stall information (`/proc/pressure/cpu`).

The kernel adds up the time during which at least one runnable task waited for a CPU ("some",
microseconds since boot). Over a window, that time divided by the window's length says how
overloaded the machine was: near 0 on an idle machine, near 1 when something always waited. The
runner reads it only while a stream is silent, to tell a silent device from a starved machine (a
serial device's bytes reach the reader through a kernel worker thread that competes for the CPU
like any task). Where the file is missing (another kernel, another system) nothing is measured.
"""

from __future__ import annotations

import contextlib
import os
import time

__all__ = ["OVERLOADED", "CpuPressure"]

OVERLOADED = 0.5
"""The share of a window during which tasks waited for a CPU from which the machine is called
overloaded."""

PSI_CPU = "/proc/pressure/cpu"


class CpuPressure:
    """Windows of CPU pressure: `start()` marks a window's beginning, `overload()` describes the
    window so far when it was overloaded."""

    def __init__(self, path: str = PSI_CPU) -> None:
        self._fd: int | None = None
        with contextlib.suppress(OSError):
            self._fd = os.open(path, os.O_RDONLY)
        self._start: tuple[float, float] | None = None

    @property
    def available(self) -> bool:
        return self._fd is not None

    def waited_s(self) -> float | None:
        """Total time [s] some task waited for a CPU, since boot (None: not measurable)."""
        if self._fd is None:
            return None
        try:
            text = os.pread(self._fd, 256, 0).decode("ascii", "replace")
        except OSError:
            return None
        for line in text.splitlines():
            if line.startswith("some "):
                for field in line.split()[1:]:
                    key, _, value = field.partition("=")
                    if key == "total" and value.isdigit():
                        return 1e-6 * int(value)
        return None

    def start(self) -> None:
        """Begin a window now (again, if one was open)."""
        waited = self.waited_s()
        self._start = None if waited is None else (time.monotonic(), waited)

    def stop(self) -> None:
        self._start = None

    @property
    def open(self) -> bool:
        return self._start is not None

    def share(self) -> tuple[float, float] | None:
        """(the window's length [s], the share of it during which tasks waited for a CPU)."""
        waited = self.waited_s()
        if self._start is None or waited is None:
            return None
        length = time.monotonic() - self._start[0]
        if length <= 0.0:
            return None
        return length, min(1.0, max(0.0, (waited - self._start[1]) / length))

    def overload(self) -> str | None:
        """A description of the window so far if the machine was overloaded in it, else None."""
        measured = self.share()
        if measured is None or measured[1] < OVERLOADED:
            return None
        length, share = measured
        return (
            f"this machine was overloaded: tasks waited for a CPU {100 * share:.0f} % of the "
            f"last {1e3 * length:.0f} ms"
        )

    def close(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
