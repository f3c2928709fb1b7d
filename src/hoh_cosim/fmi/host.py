"""What an FMU needs of the Python that hosts it, checked before the FMU imports anything else.

A pythonfmu FMU runs in the Python of the process that loads it (fmpy's, a tool's embedded one): it
carries the project's code in its `resources/` (`hoh_cosim.fmi.build`), but the packages that code
imports must be installed there. The build writes them into `resources/requirements.txt`, one
requirement a line as pip takes them (`numpy>=1.24`), with a first comment line giving the oldest
Python the code runs on. An entry script calls `require(__file__, NAME)` first; a host that lacks
something gets one line naming it and the `pip install` that fixes it, and the FMU fails to
instantiate (fmi2Instantiate returns NULL: fmi2Fatal) instead of failing later in a step.

pythonfmu's wrapper passes the FMU's log messages, the fatal one of a failed instantiation
included, to the importer's logger only when debug logging is on, so the line is also written to
the host's standard error, where a user of `fmpy simulate` sees it.

This module uses the standard library only: it runs before numpy is known to be there.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import platform
import re
import sys
from pathlib import Path

__all__ = ["REQUIREMENTS", "MissingRequirementError", "module_name", "python_line", "require"]

REQUIREMENTS = "requirements.txt"
_PYTHON = re.compile(r"#\s*python\s*>=\s*(\d+)\.(\d+)")
_LINE = re.compile(r"([A-Za-z0-9_.-]+)\s*(?:>=\s*([0-9][0-9.]*))?\s*$")
_MODULES = {"pyyaml": "yaml", "pin": "pinocchio"}  # distributions whose module has another name


class MissingRequirementError(ImportError):
    """The host's Python lacks what the FMU needs (the message is the one line to show)."""


def python_line(oldest: tuple[int, int]) -> str:
    """The requirements file's first line: the oldest Python the FMU's code runs on."""
    return f"# python >= {oldest[0]}.{oldest[1]}"


def module_name(distribution: str) -> str:
    """The module a distribution installs, for the ones the FMUs may need (`pin`: pinocchio)."""
    return _MODULES.get(distribution.lower(), distribution.replace("-", "_"))


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", text)[:3])


def require(entry_script: str, model: str) -> None:
    """Check the host against the `requirements.txt` beside `entry_script` (the FMU's resources);
    raise `MissingRequirementError` with one line, also written to standard error, if it falls short.
    Beside an entry script that has no such file (the project's own `fmus/`), there is nothing
    to check: the project's environment is the FMU's."""
    path = Path(entry_script).resolve().parent / REQUIREMENTS
    if not path.is_file():
        return
    problem = _shortfall(path.read_text(encoding="utf-8"), model)
    if problem is not None:
        print(problem, file=sys.stderr, flush=True)
        raise MissingRequirementError(problem)


def _shortfall(text: str, model: str) -> str | None:
    here = f"the host's Python ({platform.python_version()}, {sys.executable or 'embedded'})"
    for line in text.splitlines():
        line = line.strip()
        found = _PYTHON.fullmatch(line)
        if found:
            oldest = (int(found[1]), int(found[2]))
            if sys.version_info[:2] < oldest:
                return f"{model}: needs Python {oldest[0]}.{oldest[1]} or newer; {here} is older"
            continue
        if not line or line.startswith("#"):
            continue
        found = _LINE.fullmatch(line)
        if found is None:
            return f"{model}: resources/{REQUIREMENTS}: cannot read the line {line!r}"
        name, least = found[1], found[2]
        if importlib.util.find_spec(module_name(name)) is None:
            return f"{model}: needs {name}, which {here} lacks: pip install '{line}'"
        if least is not None:
            try:
                have = importlib.metadata.version(name)
            except importlib.metadata.PackageNotFoundError:
                continue  # importable but not installed as a distribution: take it as it is
            if _version(have) < _version(least):
                return (
                    f"{model}: needs {name} {least} or newer, {here} has {have}: "
                    f"pip install '{line}'"
                )
    return None
