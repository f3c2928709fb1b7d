"""numba's `njit` and `types`, or, where numba is not installed, stand-ins that leave the kernels
plain Python.

The compiled kernels (`hoh_cosim.control.kernels`, `plant_models.kernels`) are the default wherever
numba is installed. An FMU's host may have only numpy and scipy (`hoh_cosim.fmi.host`): there the
modules still import, `HAVE_NUMBA` is False, `kernels_enabled()` is False, and the blocks take the
pure path they are checked against. A kernel function called without numba runs as the plain
Python it is written in (the UR5's kinematics in an FMU whose host has no pinocchio, for one).
"""

from __future__ import annotations

import types as _pytypes
from collections.abc import Callable
from typing import Any

__all__ = ["HAVE_NUMBA", "njit", "types"]

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
