"""Reading the project's YAML files (scenarios, hardware configurations) with one-line errors.

Every mistake is a `ConfigError` whose message starts with the file and the YAML path of the value:
`scenarios/x.yaml: components.plant.every: expected an integer >= 1, got 0`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hoh_cosim.errors import ConfigError

__all__ = ["Where", "parse_value", "read_yaml"]


def read_yaml(path: Path) -> Any:
    """The file's YAML document; a missing, unreadable or malformed file is a one-line error."""
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise Where(path).error(where, f"not valid YAML: {problem}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None


def parse_value(option: str, text: str) -> Any:
    """The value of a `--set name=VALUE` option, read as YAML (`0.5`, `true`, `[1, 2, 3]`)."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or "not valid YAML"
        name = option.partition("=")[0]
        raise ConfigError(f"--set {name}: cannot read the value {text!r}: {problem}") from None


class Where:
    """One file: builds its errors and checks its values, each named by its YAML path."""

    def __init__(self, path: Path | str) -> None:
        self.file = str(path)

    def error(self, where: str, problem: str) -> ConfigError:
        return ConfigError(
            f"{self.file}: {where}: {problem}" if where else f"{self.file}: {problem}"
        )

    def number(self, value: Any, where: str, *, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
            raise self.error(where, f"expected a number, got {value!r}")
        if positive and value <= 0:
            raise self.error(where, f"expected a number > 0, got {value!r}")
        return float(value)

    def integer(self, value: Any, where: str, *, low: int = 0, high: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise self.error(where, f"expected an integer >= {low}, got {value!r}")
        if high is not None and value > high:
            raise self.error(where, f"expected an integer <= {high}, got {value!r}")
        return value

    def string(self, value: Any, where: str, *, choices: Sequence[str] = ()) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(where, f"expected a non-empty string, got {value!r}")
        if choices and value not in choices:
            raise self.error(where, f"expected one of {', '.join(choices)}, got {value!r}")
        return value

    def boolean(self, value: Any, where: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(where, f"expected true or false, got {value!r}")
        return value

    def mapping(self, value: Any, keys: Sequence[str], where: str) -> Mapping[str, Any]:
        """`value` as a mapping whose keys are all among `keys`."""
        if not isinstance(value, Mapping):
            raise self.error(where, f"expected a mapping, got {value!r}")
        for key in value:
            if key not in keys:
                raise self.error(
                    f"{where}.{key}" if where else str(key),
                    f"unknown key (expected one of: {', '.join(keys)})",
                )
        return value
