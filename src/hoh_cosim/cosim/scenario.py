"""Scenario files: YAML in, typed and validated objects out.

    extends: base.yaml               # optional: start from another scenario (path from this file);
                                     # mappings merge key by key, lists and values replace
    name: circles
    description: the operator draws circles in the air (seed Fig. 20, 21)
    preset: seed                     # the estimator's and the controller's parameters before the
                                     # file's own (hoh_cosim.presets; default: DEFAULT_PRESET)
    duration_s: 30.0
    dt_s: 0.001                      # the master's tick
    seed: 7                          # every random source derives from it
    metrics: circles                 # which metrics and plots
    probe_sensor: fse103             # or loadcell, or none (hoh_cosim.cosim.probe_sensor)
    components:                      # stepped in this order, each every `every` ticks
      operator: {params: {task: circle, start_s: 3.0}}
      plant: {}
      controller: {kind: controller, every: 8, params: {contact_compensation: true}}
      probe: {kind: fse103, fmu: ../my/fse103.fmu}   # a given FMU (path from this file)
      ...
    connections:
      - {from: operator.F_hand_B, to: plant.F_hand_B}       # whole ports
      - {from: plant.force_P[3], to: fse103.force_P_true[3]} # or single elements, from 1
    inputs:                          # values for inputs nothing is connected to (a block's
      plant.tau_hand_B: [0, 0, 0]    # OPTIONAL_INPUTS may be left out: 0)
    events:
      - {at_s: 12.0, set: {operator.released: true}}       # tunable parameters only
    record: [plant.p_BT_B, operator.F_hand_B]               # signals.csv columns (default: all)
    record_every: 10                 # signals.csv keeps every 10th tick (default: every tick)

Every mistake is a `ConfigError` whose one-line message starts with the file and the YAML path:
`scenarios/x.yaml: connections[3].to: unknown port 'estimator.wrench_S[7]'`.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.control.block import Port
from hoh_cosim.control.cycle import SensorSetup
from hoh_cosim.cosim.probe_sensor import with_probe_sensor
from hoh_cosim.errors import ConfigError
from hoh_cosim.kinds import KINDS, ComponentKind, input_starts
from hoh_cosim.params import from_mapping, leaves, override
from hoh_cosim.presets import BLOCKS, DEFAULT_PRESET, Preset, changed_from, load_preset
from hoh_cosim.yamlfile import Where, parse_value, read_yaml

__all__ = [
    "METRIC_SETS",
    "TELEECHO_ARMS",
    "TELEECHO_CONTROLLERS",
    "ComponentSpec",
    "Connection",
    "Event",
    "Scenario",
    "load_scenario",
    "parse_endpoint",
]

TELEECHO_ARMS = ("panda", "plant")
"""The kinds of arm a teleecho scenario may have, in the order the report looks for them."""
TELEECHO_CONTROLLERS = ("impedance", "ur5_impedance")
"""The kinds of impedance controller a teleecho scenario may have, in the same order of search."""
METRIC_SETS: dict[str, tuple[str | tuple[str, ...], ...]] = {
    "none": (),
    "circles": ("operator", "plant", "estimator"),
    "static_noise": ("estimator",),
    "gravity_calibration": ("sequencer", "plant", "ft150"),
    "contact_scan": ("operator", "plant"),
    "release": ("operator", "plant"),
    "teleecho": (TELEECHO_ARMS, TELEECHO_CONTROLLERS),
    "probe_data": ("estimator", "fse103", "plant"),
    "clinical": ("operator", ("plant", "freehand")),
}
"""Each metric set (see `hoh_cosim.cosim.report`) and the kinds of component it reads (a tuple:
any one of those kinds). The one list of metric sets: the report's and the plots' tables have one
entry per key (tests/unit/test_closed_sets.py)."""
_TOP_KEYS = (
    "extends",
    "name",
    "description",
    "preset",
    "duration_s",
    "dt_s",
    "seed",
    "metrics",
    "probe_sensor",
    "components",
    "connections",
    "inputs",
    "events",
    "record",
    "record_every",
)
_COMPONENT_KEYS = ("kind", "every", "params", "fmu")
_ENDPOINT = re.compile(
    r"^(?P<component>[A-Za-z_]\w*)\.(?P<port>[A-Za-z_]\w*)(\[(?P<index>\d+)\])?$"
)


@dataclass(frozen=True)
class ComponentSpec:
    name: str
    kind: ComponentKind
    every: int
    params: Any
    seed: int
    fmu: Path | None = None  # a given FMU file instead of the one built from fmus/

    @property
    def inputs(self) -> tuple[Port, ...]:
        return self.kind.block.inputs

    @property
    def outputs(self) -> tuple[Port, ...]:
        return self.kind.block.outputs


@dataclass(frozen=True)
class Connection:
    """Output elements of one component feeding input elements of another (sizes equal)."""

    src: str
    src_port: str
    src_elements: tuple[int, ...]  # 0-based element indices within the port
    dst: str
    dst_port: str
    dst_elements: tuple[int, ...]


@dataclass(frozen=True)
class Event:
    """At `time_s`, the leaves of one component's parameters change (tunable ones only)."""

    time_s: float
    component: str
    changes: dict[str, Any]  # leaf name -> value, as `hoh_cosim.params.leaves` names them
    params: Any  # the component's full parameters after the change, validated


@dataclass(frozen=True)
class Scenario:
    path: Path
    name: str
    description: str
    duration_s: float
    dt_s: float
    seed: int
    metrics: str
    components: dict[str, ComponentSpec]  # in stepping order
    connections: tuple[Connection, ...]
    input_defaults: dict[tuple[str, str], np.ndarray]  # (component, port) -> full port value
    events: tuple[Event, ...]
    record: tuple[str, ...]  # "component.port"
    record_every: int = 1  # signals.csv keeps every n-th tick (the metrics use them all)
    preset: Preset | None = None  # the estimator's and the controller's preset (None: neither)

    def preset_changes(self) -> dict[str, Any]:
        """Every value of the estimator's and the controller's parameters that differs from the
        preset (the file's own and `--set`), as `component.leaf` names."""
        if self.preset is None:
            return {}
        return {
            f"{c.name}.{name}": value
            for c in self.components.values()
            if c.kind.name in BLOCKS
            for name, value in changed_from(self.preset.params[c.kind.name], c.params).items()
        }

    @property
    def n_ticks(self) -> int:
        return round(self.duration_s / self.dt_s)

    def component_of_kind(self, kind: str) -> ComponentSpec | None:
        return next((c for c in self.components.values() if c.kind.name == kind), None)

    def component_of_kinds(self, kinds: Sequence[str]) -> ComponentSpec | None:
        """A component of the first of `kinds` that the scenario has."""
        return next((c for k in kinds if (c := self.component_of_kind(k)) is not None), None)


def component_seed(scenario_seed: int, name: str) -> int:
    """A component's seed: independent per component, fixed by the scenario's seed and its name."""
    state = np.random.SeedSequence([scenario_seed, zlib.crc32(name.encode())])
    return int(state.generate_state(1)[0] & 0x7FFFFFFF)


def parse_endpoint(
    text: Any, components: Mapping[str, ComponentSpec], direction: str, where: str, w: Where
) -> tuple[str, Port, tuple[int, ...]]:
    """`component.port` or `component.port[i]` -> (component, port, 0-based elements)."""
    if not isinstance(text, str) or (match := _ENDPOINT.match(text.strip())) is None:
        raise w.error(where, f"expected 'component.port' or 'component.port[i]', got {text!r}")
    name, port_name, index = match["component"], match["port"], match["index"]
    if name not in components:
        raise w.error(where, f"unknown component {name!r} (components: {', '.join(components)})")
    spec = components[name]
    ports = {p.name: p for p in (spec.outputs if direction == "from" else spec.inputs)}
    kind = "output" if direction == "from" else "input"
    if port_name not in ports:
        raise w.error(
            where, f"unknown {kind} port '{text.strip()}' ({kind}s of {name}: {', '.join(ports)})"
        )
    port = ports[port_name]
    if index is None:
        return name, port, tuple(range(port.size))
    i = int(index)
    if not 1 <= i <= port.size:
        raise w.error(
            where, f"unknown port '{text.strip()}' ({port_name} has elements 1 to {port.size})"
        )
    return name, port, (i - 1,)


def _component(
    name: str, raw: Any, seed: int, w: Where, preset: Preset | None = None
) -> ComponentSpec:
    where = f"components.{name}"
    raw = w.mapping(raw if raw is not None else {}, _COMPONENT_KEYS, where)
    kind_name = raw.get("kind", name)
    if not isinstance(kind_name, str) or kind_name not in KINDS:
        raise w.error(
            f"{where}.kind" if "kind" in raw else where,
            f"unknown component kind {kind_name!r} (kinds: {', '.join(KINDS)})",
        )
    kind = KINDS[kind_name]
    every = w.integer(raw.get("every", 1), f"{where}.every", low=1)
    base = preset.params[kind_name] if preset is not None and kind_name in BLOCKS else kind.params()
    try:
        params = from_mapping(base, raw.get("params") or {}, f"{where}.params")
    except ConfigError as exc:
        raise ConfigError(f"{w.file}: {exc}") from None
    fmu = None
    if "fmu" in raw:
        if not isinstance(raw["fmu"], str) or not raw["fmu"]:
            raise w.error(f"{where}.fmu", f"expected the path of an .fmu file, got {raw['fmu']!r}")
        fmu = (Path(w.file).parent / raw["fmu"]).resolve()
        if not fmu.is_file():
            raise w.error(f"{where}.fmu", f"no such FMU '{raw['fmu']}' (looked for {fmu})")
    return ComponentSpec(name, kind, every, params, component_seed(seed, name), fmu)


def _merge(base: Any, change: Any) -> Any:
    """`change` laid over `base`: mappings merge key by key, anything else is replaced."""
    if isinstance(base, Mapping) and isinstance(change, Mapping):
        out = dict(base)
        for key, value in change.items():
            out[key] = _merge(base[key], value) if key in base else value
        return out
    return change


def _read_raw(path: Path, seen: tuple[Path, ...]) -> Any:
    """The file's YAML with its `extends:` chain resolved (the base checked on its own first, so a
    mistake in the base is reported against the base)."""
    raw = read_yaml(path)
    if not isinstance(raw, Mapping) or "extends" not in raw:
        return raw
    w = Where(path)
    base_name = raw["extends"]
    if not isinstance(base_name, str) or not base_name:
        raise w.error("extends", f"expected the path of a scenario file, got {base_name!r}")
    base_path = path.parent / base_name
    if base_path.resolve() in seen or base_path.resolve() == path.resolve():
        raise w.error("extends", f"'{base_name}' extends this file again (a cycle)")
    if not base_path.is_file():
        raise w.error("extends", f"no such scenario '{base_name}' (looked for {base_path})")
    base = _read_raw(base_path, (*seen, path.resolve()))
    load_scenario(base_path)
    return _merge(base, {k: v for k, v in raw.items() if k != "extends"})


def load_scenario(
    path: str | Path,
    overrides: Sequence[str] = (),
    duration_s: float | None = None,
    seed: int | None = None,
    preset: str | Path | None = None,
) -> Scenario:
    """Read and check a scenario; `overrides` are `component.path=value` strings (`--set`),
    `preset` a preset's name or file (`--preset`; default: the file's `preset`, else
    `hoh_cosim.presets.DEFAULT_PRESET`), applied to the estimator and the controller before the
    file's own parameters, with its session steps (the probe check: the hand's pushes before its
    task, which starts and ends that much later)."""
    path = Path(path)
    w = Where(path)
    raw = _read_raw(path, ())
    raw = with_probe_sensor(w.mapping(raw, _TOP_KEYS, ""), w)
    for key in ("name", "duration_s", "components"):
        if key not in raw:
            raise w.error(key, "missing")
    name = raw["name"]
    if not isinstance(name, str) or not name:
        raise w.error("name", f"expected a non-empty string, got {name!r}")
    duration = w.number(raw["duration_s"], "duration_s", positive=True)
    if duration_s is not None:
        duration = w.number(duration_s, "--duration", positive=True)
    dt = w.number(raw.get("dt_s", 0.001), "dt_s", positive=True)
    if dt > duration:
        raise w.error(
            "dt_s" if duration_s is None else "--duration",
            f"the run is shorter than one tick: duration {duration} s, tick {dt} s",
        )
    scenario_seed = w.integer(raw.get("seed", 0), "seed")
    if seed is not None:
        scenario_seed = w.integer(seed, "--seed")
    metrics = raw.get("metrics", "none")
    if not isinstance(metrics, str) or metrics not in METRIC_SETS:
        raise w.error("metrics", f"expected one of {', '.join(METRIC_SETS)}, got {metrics!r}")
    record_every = w.integer(raw.get("record_every", 1), "record_every", low=1)

    components_raw = raw["components"]
    names = list(components_raw) if isinstance(components_raw, Mapping) else []
    raw_components = w.mapping(components_raw, names, "components")
    if not raw_components:
        raise w.error("components", "expected at least one component")
    chosen = _preset(raw, preset, raw_components, w)
    components = {n: _component(n, c, scenario_seed, w, chosen) for n, c in raw_components.items()}
    if chosen is not None and chosen.probe_check_s > 0.0:
        duration += _probe_check(components, chosen.probe_check_s, duration_s is None)
    kinds = {c.kind.name for c in components.values()}
    for needed in METRIC_SETS[metrics]:
        alternatives = (needed,) if isinstance(needed, str) else needed
        if not kinds.intersection(alternatives):
            wanted = " or ".join(repr(k) for k in alternatives)
            raise w.error(
                "metrics",
                f"the {metrics} metrics need a component of kind {wanted}; there is none",
            )

    for text in overrides:
        target, sep, value_text = text.partition("=")
        where = f"--set {target}"
        component, _, param_path = target.partition(".")
        if not sep or not param_path:
            raise ConfigError(f"--set {text}: expected component.parameter=value")
        if component not in components:
            raise ConfigError(
                f"{where}: unknown component {component!r} (components: {', '.join(components)})"
            )
        value = parse_value(text, value_text)
        spec = components[component]
        new = override(spec.params, param_path, value, f"--set {component}")
        components[component] = dataclasses.replace(spec, params=new)

    connections, fed = _connections(raw.get("connections") or [], components, w)
    _share_sensors(components, connections, w)
    defaults = _input_defaults(raw.get("inputs") or {}, components, w)
    for comp in components.values():
        for port in comp.inputs:
            if (comp.name, port.name) in defaults:
                both = [
                    fed[key] for i in range(port.size) if (key := (comp.name, port.name, i)) in fed
                ]
                if both:
                    raise w.error(
                        f"inputs.{comp.name}.{port.name}",
                        f"the input is also fed by connections[{both[0]}]: give it one source",
                    )
                continue
            missing = [i for i in range(port.size) if (comp.name, port.name, i) not in fed]
            optional = getattr(comp.kind.block, "OPTIONAL_INPUTS", frozenset())
            if len(missing) == port.size and port.name in optional:  # left out: at rest
                defaults[(comp.name, port.name)] = _resting_input(comp.kind.name, port.name)
                continue
            if missing:
                element = port.name if port.size == 1 else f"{port.name}[{missing[0] + 1}]"
                raise w.error(
                    "connections",
                    f"input '{comp.name}.{element}' is not connected "
                    f"and has no value under 'inputs'",
                )
    events = _events(raw.get("events") or [], components, duration, w)
    record = _record(raw.get("record"), components, w)
    description = raw.get("description", "")
    if not isinstance(description, str):
        raise w.error("description", f"expected a string, got {description!r}")
    return Scenario(
        path,
        name,
        description,
        duration,
        dt,
        scenario_seed,
        metrics,
        components,
        tuple(connections),
        defaults,
        tuple(events),
        tuple(record),
        record_every,
        chosen,
    )


def _preset(
    raw: Mapping[str, Any], preset: str | Path | None, components: Mapping[str, Any], w: Where
) -> Preset | None:
    """The scenario's preset: `--preset`, else the file's, else the default; None when no
    component is an estimator or a controller (nothing to apply it to)."""
    name: Any = preset
    if name is None:
        name = raw.get("preset", DEFAULT_PRESET)
        if not isinstance(name, str) or not name:
            raise w.error("preset", f"expected a preset's name or a file's path, got {name!r}")
        if name.endswith((".yaml", ".yml")) or "/" in name:
            name = Path(w.file).parent / name
    try:
        chosen = load_preset(name)
    except ConfigError as exc:
        if preset is not None:  # the command line's: no file to name
            raise
        raise ConfigError(f"{w.file}: {exc}") from None
    kinds = [c.get("kind", n) if isinstance(c, Mapping) else n for n, c in components.items()]
    return chosen if any(isinstance(k, str) and k in BLOCKS for k in kinds) else None


def _probe_check(components: dict[str, ComponentSpec], check_s: float, longer: bool) -> float:
    """The preset's probe check in a co-simulation: the hand pushes the probe's tip for
    `check_s` before its task (`plant_models.operator`), which starts that much later; the run's
    extra length (when `longer`: no `--duration`). A scenario whose hand already checks the probe
    keeps its own check."""
    extra = 0.0
    for name, spec in components.items():
        if spec.kind.name != "operator" or spec.params.probe_check_s > 0.0:
            continue
        # the task's clock moves: its start and the one time given on the run's clock (the
        # push_release task's release)
        params = dataclasses.replace(
            spec.params,
            probe_check_s=check_s,
            start_s=spec.params.start_s + check_s,
            release_s=spec.params.release_s + check_s,
        )
        components[name] = dataclasses.replace(spec, params=params)
        extra = check_s if longer else 0.0
    return extra


@functools.cache
def _resting_start(kind: str, port: str) -> tuple[float, ...] | None:
    value = input_starts(kind).get(port)
    return None if value is None else tuple(value.tolist())


def _resting_input(kind: str, port: str) -> np.ndarray:
    """An optional input nothing feeds: where a world at rest has it (`input_starts`), else 0."""
    start = _resting_start(kind, port)
    size = next(p.size for p in KINDS[kind].block.inputs if p.name == port)
    return np.zeros(size) if start is None else np.array(start)


def _connections(
    raw: Any, components: dict[str, ComponentSpec], w: Where
) -> tuple[list[Connection], dict[tuple[str, str, int], int]]:
    """The connections, and for every input element fed which connection feeds it."""
    if not isinstance(raw, list):
        raise w.error("connections", f"expected a list, got {raw!r}")
    out: list[Connection] = []
    fed: dict[tuple[str, str, int], int] = {}
    for i, item in enumerate(raw):
        where = f"connections[{i}]"
        item = w.mapping(item, ("from", "to"), where)
        for key in ("from", "to"):
            if key not in item:
                raise w.error(f"{where}.{key}", "missing")
        src, src_port, src_el = parse_endpoint(item["from"], components, "from", f"{where}.from", w)
        dst, dst_port, dst_el = parse_endpoint(item["to"], components, "to", f"{where}.to", w)
        if len(src_el) != len(dst_el):
            raise w.error(
                where,
                f"sizes differ: {item['from']} has {len(src_el)} values, "
                f"{item['to']} takes {len(dst_el)}",
            )
        for e in dst_el:
            key = (dst, dst_port.name, e)
            if key in fed:
                raise w.error(
                    f"{where}.to", f"{item['to']} is already fed by connections[{fed[key]}]"
                )
            fed[key] = i
        out.append(Connection(src, src_port.name, src_el, dst, dst_port.name, dst_el))
    return out, fed


def _share_sensors(
    components: dict[str, ComponentSpec], connections: Sequence[Connection], w: Where
) -> None:
    """A controller fed by an estimator sees the rig's sensors as the estimator does: the packet
    periods and `use_probe` are given once, in the estimator's parameters."""
    for src, dst in dict.fromkeys((c.src, c.dst) for c in connections):
        estimator, controller = components[src], components[dst]
        if estimator.kind.name != "estimator" or controller.kind.name != "controller":
            continue
        names = (f"components.{src}.params", f"components.{dst}.params")
        try:
            sensors = SensorSetup.shared(estimator.params, controller.params, names)
        except ConfigError as exc:
            raise w.error("", str(exc)) from None
        try:  # the controller's parameters are checked again as they are rebuilt
            _, params = sensors.apply(estimator.params, controller.params)
        except ConfigError as exc:
            raise w.error(names[1], str(exc)) from None
        components[dst] = dataclasses.replace(controller, params=params)


def _input_defaults(
    raw: Any, components: dict[str, ComponentSpec], w: Where
) -> dict[tuple[str, str], np.ndarray]:
    raw = w.mapping(raw, list(raw) if isinstance(raw, Mapping) else [], "inputs")
    out: dict[tuple[str, str], np.ndarray] = {}
    for key, value in raw.items():
        where = f"inputs.{key}"
        name, port, elements = parse_endpoint(key, components, "to", where, w)
        if len(elements) != port.size:
            raise w.error(where, "give a value for the whole port")
        values = value if isinstance(value, list) else [value]
        if len(values) != port.size:
            raise w.error(where, f"expected {port.size} values, got {len(values)}")
        out[(name, port.name)] = np.array([w.number(v, where) for v in values])
    return out


def _events(
    raw: Any, components: dict[str, ComponentSpec], duration: float, w: Where
) -> list[Event]:
    if not isinstance(raw, list):
        raise w.error("events", f"expected a list, got {raw!r}")
    out: list[Event] = []
    state = {name: spec.params for name, spec in components.items()}
    checked: list[tuple[float, int, Mapping[str, Any]]] = []
    for i, item in enumerate(raw):
        where = f"events[{i}]"
        item = w.mapping(item, ("at_s", "set"), where)
        if "at_s" not in item or "set" not in item:
            raise w.error(where, "expected at_s and set")
        at = w.number(item["at_s"], f"{where}.at_s")
        if not 0.0 <= at <= duration:
            raise w.error(f"{where}.at_s", f"expected a time within 0 to {duration} s, got {at}")
        changes = w.mapping(
            item["set"],
            list(item["set"]) if isinstance(item["set"], Mapping) else [],
            f"{where}.set",
        )
        checked.append((at, i, changes))
    for at, i, changes in sorted(checked, key=lambda c: (c[0], c[1])):  # in time, then file order
        where = f"events[{i}]"
        by_component: dict[str, dict[str, Any]] = {}
        for target, value in changes.items():
            here = f"{where}.set.{target}"
            component, _, param_path = str(target).partition(".")
            if not param_path:
                raise w.error(here, "expected component.parameter")
            if component not in components:
                raise w.error(
                    here,
                    f"unknown component {component!r} (components: {', '.join(components)})",
                )
            before = {leaf.name: leaf for leaf in leaves(state[component])}
            try:
                new = override(state[component], param_path, value, f"{where}.set.{component}")
            except ConfigError as exc:
                raise ConfigError(f"{w.file}: {exc}") from None
            changed = {
                leaf.name: leaf.value
                for leaf in leaves(new)
                if before[leaf.name].value != leaf.value
            }
            fixed = [n for n in changed if not before[n].tunable]
            if fixed:
                raise w.error(
                    here,
                    f"{component}.{fixed[0]} cannot change during a run (not a tunable parameter)",
                )
            state[component] = new
            by_component.setdefault(component, {}).update(changed)
        for component, leaf_changes in by_component.items():
            out.append(Event(at, component, leaf_changes, state[component]))
    return out


def _record(raw: Any, components: dict[str, ComponentSpec], w: Where) -> list[str]:
    every = [f"{c.name}.{p.name}" for c in components.values() for p in c.outputs]
    if raw is None:
        return every
    if not isinstance(raw, list):
        raise w.error("record", f"expected a list of component.port, got {raw!r}")
    out = []
    for i, item in enumerate(raw):
        name, port, elements = parse_endpoint(item, components, "from", f"record[{i}]", w)
        if len(elements) != port.size:
            raise w.error(f"record[{i}]", "record whole ports")
        if f"{name}.{port.name}" in out:
            raise w.error(f"record[{i}]", f"{item} is already recorded")
        out.append(f"{name}.{port.name}")
    return out
