"""How starved the machine's CPU is: Linux's pressure stall information (`/proc/pressure/cpu`), and
a canary process of ordinary priority that counts the time it could not run.

The kernel adds up the time during which at least one runnable task waited for a CPU ("some",
microseconds since boot). Over a window, that time divided by the window's length says how
overloaded the machine was: near 0 on an idle machine, near 1 when something always waited. The
runner reads it only while a stream is silent, to tell a silent device from a starved machine (a
serial device's bytes reach the reader through a kernel worker thread that competes for the CPU
like any task). Where the file is missing (another kernel, another system) nothing is measured.

The pressure says that *some* task waited; `Canary` says whether an ordinary one could run at all.
It is a small process at the default policy and priority (SCHED_OTHER, like the kernel worker that
delivers a serial port's bytes), ticking every `tick_s` and writing its figures into a shared
page; a tick that comes more than `allowance_s` late adds its lateness to the starved time. On a
machine where the real-time threads (the loop, the readers, a simulated world) and other work leave
no CPU to ordinary tasks, the canary starves with the worker, and the supervisor does not count
that time as the device's silence (`hoh_cosim.control.supervisor`).
"""

from __future__ import annotations

import contextlib
import mmap
import os
import struct
import subprocess
import sys
import tempfile
import time

__all__ = ["OVERLOADED", "Canary", "CpuPressure"]

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


CANARY_CODE = """
import mmap, os, struct, sys, threading, time
fd, tick_s, allowance_s, parent = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), os.getppid()
cores = [int(core) for core in sys.argv[4].split(",")]
page = mmap.mmap(fd, 16 * len(cores))
def tick(slot, core):
    try:  # this thread on this core alone: it starves when that core's ordinary tasks do
        os.sched_setaffinity(threading.get_native_id(), {core})
    except OSError:  # the core was taken away meanwhile: the thread still ticks, anywhere
        pass
    starved, last = 0.0, time.monotonic()
    struct.pack_into("d", page, 16 * slot + 8, last)
    while os.getppid() == parent:  # the runner gone (even killed), the canary goes too
        time.sleep(tick_s)
        now = time.monotonic()
        late, last = now - last - allowance_s, now
        struct.pack_into("d", page, 16 * slot + 8, last)  # before the total: see Canary.starved_s
        if late > 0.0:
            starved += late
            struct.pack_into("d", page, 16 * slot, starved)
threads = [threading.Thread(target=tick, args=slot_core) for slot_core in enumerate(cores)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
"""


class Canary:
    """A process of ordinary priority whose late ticks measure how long ordinary tasks were starved
    of the CPU, on each core apart: one thread per core the runner may use, bound to that core.
    `starved_s()` is each core's total so far, a tick still overdue included; `since(mark)` the
    most any core starved since `starved_s()` returned `mark`.

    Per core, because an ordinary task waits on the core it was queued on: a serial port's bytes
    are delivered by a kernel worker that can wait on a core monopolised by real-time work while
    the other core runs ordinary tasks freely (one unbound canary, on the free core, saw nothing
    of it: a spurious "no new sample for 252 ms" in a loaded suite). The most any core starved
    is at least what the worker waited; it may be more, and the supervisor's cap on a stale
    stream's age (`stale_stop_max_s`) bounds what that costs.

    A process, not a thread of the runner: a thread of ordinary priority would hold the runner's
    GIL while it ticks, and a starved one would hold it for as long as it starves, with the
    real-time loop waiting for it (seen: 715 ms, in a loaded suite). Within the canary a starved
    thread holding the GIL only delays the other cores' threads by as long as its own core
    starves, which the most over cores counts anyway."""

    def __init__(self, tick_s: float = 0.005, allowance_s: float = 0.02) -> None:
        self.allowance_s = allowance_s
        self.cores = tuple(sorted(os.sched_getaffinity(0)))
        size = _SLOT * len(self.cores)
        self._file = tempfile.TemporaryFile(  # noqa: SIM115 - closed by close()
            dir="/dev/shm" if os.path.isdir("/dev/shm") else None
        )
        self._file.truncate(size)
        self._page = mmap.mmap(self._file.fileno(), size)
        # until its first tick a core's thread counts as having just ticked, however slowly the
        # canary starts
        for slot in range(len(self.cores)):
            _DOUBLE.pack_into(self._page, _SLOT * slot + 8, time.monotonic() + 1.0)
        fd = self._file.fileno()
        cores = ",".join(str(core) for core in self.cores)
        self._process = subprocess.Popen(
            [
                sys.executable,
                "-S",
                "-c",
                CANARY_CODE,
                str(fd),
                repr(tick_s),
                repr(allowance_s),
                cores,
            ],
            pass_fds=(fd,),
            stdin=subprocess.DEVNULL,
        )

    def starved_s(self) -> tuple[float, ...]:
        """Per core (in the order of `cores`), the seconds its thread could not run beyond its
        allowance, since the canary started, up to now."""
        now = time.monotonic()
        totals = []
        for slot in range(len(self.cores)):
            # a thread writes its last tick before its total, this reads them the other way
            # round: a tick in between can only leave its lateness out, never count it twice
            (starved,) = _DOUBLE.unpack_from(self._page, _SLOT * slot)
            (last,) = _DOUBLE.unpack_from(self._page, _SLOT * slot + 8)
            totals.append(starved + max(0.0, now - last - self.allowance_s))
        return tuple(totals)

    def since(self, mark: tuple[float, ...]) -> float:
        """The most any core was starved since `starved_s()` returned `mark` [s]."""
        return max(now - then for now, then in zip(self.starved_s(), mark, strict=True))

    def close(self) -> None:
        if self._process.poll() is None:
            self._process.kill()
        self._process.wait()
        self._page.close()
        self._file.close()


_DOUBLE = struct.Struct("d")
_SLOT = 16  # a core's figures: its starved total, then its last tick
