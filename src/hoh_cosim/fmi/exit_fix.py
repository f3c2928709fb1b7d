"""Unload pythonfmu FMUs, and exit a process that loaded them, without corrupting its memory.

pythonfmu 0.7.0 keeps its interpreter state in a static `std::shared_ptr` and also resets that
pointer from a library destructor (`finalizePythonInterpreter`). When the library is unloaded (fmpy's
`freeInstance()` unloads it) or the process exits with it loaded, the C++ runtime destroys the static
first and the destructor then resets the destroyed pointer: the same control block is released twice.
Valgrind shows the invalid access in `finalizePythonInterpreter`; the damage surfaces later and
elsewhere: "corrupted double-linked list" at exit, or a segmentation fault in some unrelated garbage
collection (here: 2 exits in 60 aborted after one instantiation; the test suite crashed in 4 of 6
runs).

The cure is to call the exported `finalizePythonInterpreter` ourselves while the static is alive:
the pointer is then empty when the runtime destroys it and when the destructor resets it again.
That is safe at any time in a process that owns its interpreter (the state then holds only an idle
thread, and the next instantiation makes it afresh). `install()` does it before fmpy unloads a
library and, at exit, for every pythonfmu library still loaded. Measured: 0 aborts in 80 exits.

A host that never installed hoh-cosim has the same defect, so our FMUs protect it themselves: the
adapter calls `protect_host()` as it is instantiated, which does what `install()` does where fmpy
is the importer, and the release at exit in any Python host (libcosimpy, ecospy). Measured: a plant
FMU run alone by `fmpy.simulate_fmu` in a clean environment died of "corrupted double-linked list"
at exit once in a suite's run without it.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
from pathlib import Path
from typing import Any

__all__ = ["install", "protect_host", "release", "release_loaded_libraries"]

_installed = False


def release(dll: Any) -> None:
    """Reset the pythonfmu state of the loaded library `dll` (a ctypes library); a library that is
    not pythonfmu's is left alone."""
    finalize = getattr(dll, "finalizePythonInterpreter", None)
    if finalize is not None:
        finalize()


def _loaded_fmu_libraries() -> list[str]:
    maps = Path("/proc/self/maps")
    if not maps.is_file():
        return []
    paths = set()
    for line in maps.read_text().splitlines():
        fields = line.split(maxsplit=5)
        if len(fields) == 6 and "/binaries/" in fields[5]:
            paths.add(fields[5].removesuffix(" (deleted)").strip())
    return sorted(p for p in paths if p.endswith((".so", ".dylib")))


def release_loaded_libraries() -> None:
    """`release` every FMU library this process has loaded, however it was loaded (Linux: the list
    comes from /proc/self/maps; elsewhere this does nothing)."""
    for path in _loaded_fmu_libraries():
        try:  # only a library that is loaded: RTLD_NOLOAD never loads one
            dll = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:
            continue
        release(dll)


def protect_host() -> None:
    """From inside an FMU, once per process: `install()` if fmpy is the importer, else the
    release at exit alone (Linux)."""
    if _installed:
        return
    if "fmpy.fmi1" in sys.modules:
        install()
        return
    if sys.platform.startswith("linux"):
        atexit.register(release_loaded_libraries)
    _mark_installed()


def _mark_installed() -> None:
    global _installed
    _installed = True


def install() -> None:
    """Once per process: fmpy releases pythonfmu's state before it unloads a library, and every
    pythonfmu library still loaded at exit is released first. Harmless for other FMUs."""
    global _installed
    if _installed:
        return
    from fmpy.fmi1 import _FMU

    unload = _FMU.freeLibrary

    def free_library(self: Any) -> None:
        release(self.dll)
        unload(self)

    _FMU.freeLibrary = free_library  # type: ignore[method-assign]
    if sys.platform.startswith("linux"):
        atexit.register(release_loaded_libraries)
    _installed = True
