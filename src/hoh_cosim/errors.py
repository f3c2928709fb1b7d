"""The project's one exception hierarchy.

User mistakes (a bad parameter, a bad file, a pose set that cannot be identified) are `HohError`
subclasses whose message is a single line fit to show without a traceback; the command line turns
them into exit status 2. A run that fails although its input was right raises `RunError`: exit 1.
"""

from __future__ import annotations


class HohError(Exception):
    """Base of every error the project raises on purpose."""


class ConfigError(HohError, ValueError):
    """A parameter or configuration value is wrong: says the name, what was expected, what arrived."""


class InputFileError(HohError, ValueError):
    """An input file is wrong. The message starts with the file's path and names the row, column,
    key or byte offset."""

    def __init__(self, path: object, where: str, problem: str) -> None:
        self.path = str(path)
        self.where = where
        self.problem = problem
        location = f"{self.path}: {where}: " if where else f"{self.path}: "
        super().__init__(location + problem)


class IdentificationError(HohError, ValueError):
    """The data cannot identify the parameters (too few poses, orientations too alike) or the
    result is physically implausible."""


class RunError(HohError, RuntimeError):
    """The run itself failed (an FMU reported an error, a block raised, an FMU would not build):
    the command line's exit status 1, not 2, since the input was fine."""


def io_failure(exc: OSError) -> RunError:
    """An operating system's error during a run, as one line: the file (or I/O) and the reason."""
    return RunError(f"{exc.filename or 'I/O'}: {exc.strerror or exc}")
