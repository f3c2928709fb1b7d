"""numba's `njit` and `types`, or, where numba is not installed, stand-ins that leave the kernels
plain Python.

The compiled kernels (`hoh_cosim.control.kernels`, `plant_models.kernels`) are the default wherever
numba is installed. An FMU's host may have only numpy and scipy (`hoh_cosim.fmi.host`): there the
modules still import, `HAVE_NUMBA` is False, `kernels_enabled()` is False, and the blocks take the
pure path they are checked against. A kernel function called without numba runs as the plain
Python it is written in (the UR5's kinematics in an FMU whose host has no pinocchio, for one).

Inside an FMU the kernels' sources are wherever the host unpacked it, and most hosts (fmpy's
`simulate_fmu`, libcosim, ecos) unpack it into a new temporary folder every time. numba keys its
cache by the source file's folder, so each of those loads compiled the kernels again: 7-12 s for
the plant's and the hand's before their first step. A source file inside an unpacked FMU (a
`resources/` folder beside a `modelDescription.xml`) is cached by its content instead, in numba's
user cache (or `NUMBA_CACHE_DIR`): compiled once per machine, whatever folder it is unpacked into.
numba checks the cached code against the source's content, its own version and the CPU, as for
any other cache.
"""

from __future__ import annotations

import hashlib
import os
import types as _pytypes
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["HAVE_NUMBA", "in_unpacked_fmu", "njit", "types"]

try:
    from numba import njit, types

    HAVE_NUMBA = True
except ImportError:
    HAVE_NUMBA = False

    class _Signature:
        """Stands for any numba type or signature: every attribute, item and call is itself."""

        def __getattr__(self, name: str) -> _Signature:
            return self

        def __getitem__(self, key: Any) -> _Signature:
            return self

        def __call__(self, *args: Any, **kwargs: Any) -> _Signature:
            return self

    types = _Signature()  # type: ignore[assignment]

    def njit(*args: Any, **kwargs: Any) -> Any:  # type: ignore[no-redef]
        """`@njit` and `@njit(signature, options...)` without numba: the function as written."""
        if len(args) == 1 and isinstance(args[0], _pytypes.FunctionType) and not kwargs:
            return args[0]

        def keep(function: Callable[..., Any]) -> Callable[..., Any]:
            return function

        return keep


def in_unpacked_fmu(py_file: str) -> bool:
    """Whether `py_file` lies in an unpacked FMU's `resources/` (beside its modelDescription.xml)."""
    for folder in Path(py_file).resolve().parents:
        if folder.name == "resources" and (folder.parent / "modelDescription.xml").is_file():
            return True
    return False


def _cache_unpacked_fmus_by_content() -> None:
    """Put a locator before numba's own that caches an unpacked FMU's kernels by their source's
    content (numba 0.60 and newer check a cache against the source's content, not its time)."""
    try:
        from numba.core import caching, config
    except ImportError:
        return
    impl = getattr(caching, "CacheImpl", None)
    base = getattr(caching, "UserWideCacheLocator", None)
    if impl is None or base is None:
        return  # a numba whose cache locators are not these

    class UnpackedFmuLocator(base):  # type: ignore[misc, valid-type]
        """An unpacked FMU's source file, cached by its content (see the module's docstring)."""

        def __init__(self, py_func: Any, py_file: str) -> None:
            super().__init__(py_func, py_file)
            root = config.CACHE_DIR or os.path.dirname(self._cache_path)
            self._cache_path = os.path.join(root, self.get_suitable_cache_subpath(py_file))

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if not in_unpacked_fmu(py_file):
                return None
            return super().from_function(py_func, py_file)

        @classmethod
        def get_suitable_cache_subpath(cls, py_file: str) -> str:
            digest = hashlib.sha256(Path(py_file).read_bytes()).hexdigest()[:24]
            return f"hoh-fmu_{Path(py_file).parent.name}_{Path(py_file).stem}_{digest}"

    locators = impl._locator_classes
    if not any(getattr(c, "__name__", "") == UnpackedFmuLocator.__name__ for c in locators):
        locators.insert(0, UnpackedFmuLocator)


if HAVE_NUMBA:
    _cache_unpacked_fmus_by_content()
