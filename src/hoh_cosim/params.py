"""Parameter trees: every block's nested, frozen parameter dataclasses as flat named leaves and back.

One mechanism serves the scenario files (nested YAML mappings), `--set component.path=value`,
scheduled parameter changes and the FMI parameters of the FMUs:

- `leaves(params)` lists the scalars: `filter`, `tool.mass_kg`, `hand_force_kalman.q[2]` (vector
  elements numbered from 1, as FMI's structured names are), each with its kind (real, integer,
  boolean, string), value, unit and whether it may change during a run;
- `with_values(params, {leaf name: value})` and `from_mapping(params, mapping, where)` build new,
  validated parameters, and every error names where it came from.

A parameter class declares `UNITS` (field -> unit, or a tuple of one unit per element; a parent may
override a nested field's unit with a dotted key, since a filter's units depend on what it filters)
and `TUNABLE` (fields that may change while a block runs; everything inside a tunable field is).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from hoh_cosim.errors import ConfigError

__all__ = ["Leaf", "from_mapping", "leaves", "override", "with_values"]

Kind = Literal["real", "integer", "boolean", "string"]
_INDEXED = re.compile(r"^(?P<base>.+)\[(?P<index>\d+)\]$")


@dataclass(frozen=True)
class Leaf:
    name: str
    kind: Kind
    value: float | int | bool | str
    unit: str | None
    tunable: bool


def _kind_of(value: object) -> Kind | None:
    if isinstance(value, bool | np.bool_):
        return "boolean"
    if isinstance(value, int | np.integer):
        return "integer"
    if isinstance(value, float | np.floating):
        return "real"
    if isinstance(value, str):
        return "string"
    return None


def _units_of(obj: object) -> Mapping[str, Any]:
    return getattr(type(obj), "UNITS", {})


def _walk(
    obj: object,
    prefix: str,
    context: list[tuple[str, Mapping[str, Any]]],
    tunable: bool,
    out: list[Leaf],
) -> None:
    own_tunable = getattr(type(obj), "TUNABLE", frozenset())
    context = [*context, ("", _units_of(obj))]
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        name = f"{prefix}{f.name}"
        leaf_tunable = tunable or f.name in own_tunable
        # the outermost class that names this field (by its path from there) sets its unit
        unit: Any = None
        for path, units in context:
            key = f"{path}{f.name}"
            if key in units:
                unit = units[key]
                break
        if dataclasses.is_dataclass(value):
            child_context = [(f"{p}{f.name}.", u) for p, u in context]
            _walk(value, f"{name}.", child_context, leaf_tunable, out)
        elif isinstance(value, np.ndarray | tuple):
            flat = np.asarray(value).reshape(-1)
            for i, x in enumerate(flat):
                u = unit[i] if isinstance(unit, tuple) else unit
                out.append(Leaf(f"{name}[{i + 1}]", "real", float(x), u, leaf_tunable))
        else:
            kind = _kind_of(value)
            if kind is None:
                raise ConfigError(f"{name}: cannot express a {type(value).__name__} as a parameter")
            out.append(
                Leaf(name, kind, value, unit if kind in ("real", "integer") else None, leaf_tunable)
            )


def leaves(params: object) -> list[Leaf]:
    """Every scalar of a parameter tree, in field order."""
    out: list[Leaf] = []
    _walk(params, "", [], False, out)
    return out


def _rebuild(obj: object, prefix: str, values: Mapping[str, Any], used: set[str]) -> object:
    kwargs: dict[str, Any] = {}
    changed = False
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            new = _rebuild(value, f"{name}.", values, used)
        elif isinstance(value, np.ndarray | tuple):
            flat = np.asarray(value, dtype=np.float64).reshape(-1).copy()
            hit = False
            for i in range(flat.size):
                key = f"{name}[{i + 1}]"
                if key in values:
                    flat[i] = values[key]
                    used.add(key)
                    hit = True
            if not hit:
                new = value
            elif isinstance(value, tuple):
                new = tuple(float(x) for x in flat)
            else:
                new = flat.reshape(np.shape(value))
        elif name in values:
            new = values[name]
            used.add(name)
        else:
            new = value
        changed = changed or new is not value
        kwargs[f.name] = new
    if not changed:
        return obj
    try:
        return type(obj)(**kwargs)
    except ConfigError as exc:
        raise ConfigError(f"{prefix}{exc}") from None


def with_values(params: Any, values: Mapping[str, Any]) -> Any:
    """A copy of `params` with the named leaves set (names as `leaves` gives them), validated."""
    known = {leaf.name: leaf for leaf in leaves(params)}
    checked: dict[str, Any] = {}
    for name, value in values.items():
        leaf = known.get(name)
        if leaf is None:
            raise ConfigError(f"{name}: unknown parameter of {type(params).__name__}")
        checked[name] = _coerce(value, leaf.kind, name)
    used: set[str] = set()
    return _rebuild(params, "", checked, used)


def _coerce(value: object, kind: Kind, where: str) -> object:
    if kind == "boolean":
        if not isinstance(value, bool | np.bool_):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return bool(value)
    if kind == "integer":
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    if kind == "string":
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    return float(value)


def _nested_shape(rows: list | tuple) -> tuple[int, ...]:
    lengths = {len(row) for row in rows}
    return (len(rows), lengths.pop()) if len(lengths) == 1 else ()


def _flatten_mapping(
    obj: object, mapping: Mapping[str, Any], prefix: str, where: str, out: dict[str, Any]
) -> None:
    fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}  # type: ignore[arg-type]
    if not isinstance(mapping, Mapping):
        raise ConfigError(f"{where}: expected a mapping of parameters, got {mapping!r}")
    for key, value in mapping.items():
        here = f"{where}.{key}" if where else str(key)
        if key not in fields:
            raise ConfigError(
                f"{here}: unknown parameter of {type(obj).__name__} (one of: {', '.join(fields)})"
            )
        default = fields[key]
        name = f"{prefix}{key}"
        if dataclasses.is_dataclass(default):
            _flatten_mapping(default, value, f"{name}.", here, out)
        elif isinstance(default, np.ndarray | tuple):
            shape = np.shape(default)
            size = int(np.prod(shape))
            if isinstance(value, np.ndarray):
                value = value.tolist()
            if isinstance(value, int | float | np.integer | np.floating) and not isinstance(
                value, bool | np.bool_
            ):
                value = [value] * size  # a scalar for every element
            elif (
                len(shape) > 1
                and isinstance(value, list | tuple)
                and all(isinstance(row, list | tuple) for row in value)
                and _nested_shape(value) == shape
            ):
                value = [x for row in value for x in row]  # a matrix given row by row
            if not isinstance(value, list | tuple) or len(value) != size:
                got = f"{len(value)} values" if isinstance(value, list | tuple) else repr(value)
                raise ConfigError(f"{here}: expected a list of {size} numbers, got {got}")
            for i, x in enumerate(value):
                out[f"{name}[{i + 1}]"] = _coerce(x, "real", f"{here}[{i + 1}]")
        else:
            out[name] = _coerce(value, _kind_of(default) or "real", here)


def from_mapping(params: Any, mapping: Mapping[str, Any], where: str = "") -> Any:
    """`params` with a nested mapping of overrides (as a YAML file gives them), validated.

    Vectors take a list (or one number for every element), matrices a flat list in row order or a
    list of rows. Errors name `where` plus the key path.
    """
    flat: dict[str, Any] = {}
    _flatten_mapping(params, mapping, "", where, flat)
    try:
        return _rebuild(params, "", flat, set())
    except ConfigError as exc:
        raise ConfigError(_join(where, str(exc))) from None


_LEADING_NAME = re.compile(
    r"^(?P<name>[A-Za-z_][\w.]*(\[\d+\])?)(?::\s+|\s+(?=must\b))(?P<rest>.*)$", re.S
)


def _join(where: str, message: str) -> str:
    """`where` and a message that starts with a parameter's name, as one path:
    ('components.x.params', 'tool.mass_kg must be >= 0') -> 'components.x.params.tool.mass_kg:
    must be >= 0'."""
    if not where:
        return message
    match = _LEADING_NAME.match(message)
    if match is None:
        return f"{where}: {message}"
    return f"{where}.{match['name']}: {match['rest']}"


def override(params: Any, path: str, value: Any, where: str = "") -> Any:
    """`params` with one parameter set by its dotted path: `translation.slope` (a whole vector or a
    number), `translation.slope[2]` (one element) or `contact_compensation`."""
    here = f"{where}.{path}" if where else path
    match = _INDEXED.match(path)
    if match:
        known = {leaf.name: leaf for leaf in leaves(params)}
        if path not in known:
            base = match["base"]
            size = sum(1 for name in known if name.startswith(f"{base}["))
            hint = f" ({base} has elements 1 to {size})" if size else ""
            raise ConfigError(f"{here}: unknown parameter of {type(params).__name__}{hint}")
        try:
            return with_values(params, {path: value})
        except ConfigError as exc:
            raise ConfigError(_join(where, str(exc))) from None
    nested: Any = value
    for part in reversed(path.split(".")):
        nested = {part: nested}
    return from_mapping(params, nested, where)
