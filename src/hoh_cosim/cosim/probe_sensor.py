"""A scenario's `probe_sensor`: which sensor measures the probe's contact force, fse103, loadcell or none.

The scenarios are written with the FSE103 (seed 3.B.2: the sensor the seed used). `probe_sensor`
swaps it in the file's YAML before anything is checked, so every scenario runs with either probe
sensor, or without one, and nothing else changes:

- `fse103` (the default): the file as written;
- `loadcell`: the FSE103's component becomes a `loadcell` component in its place in the order of
  stepping (with the parameters of a `loadcell` entry under `components`, if the file has one), its
  connections go to the load cell, and the plant and the estimator take the load cell's mounting
  (eq. 3, `R_SL_SEED`: the plant's `tool.R_SP`, the estimator's `R_SP`) and its line period
  (the estimator's `probe_packet_period_s`) and the contact across the probe's axis from the
  wrist (`hoh_cosim.control.loadcell.estimator_defaults`: the cell feels none of it), each only
  where the file gives none;
- `none`: the FSE103's component and its connections go, the estimator gets no probe packet
  (`force_P` 0, `probe_counter` 0) and `use_probe: false` (no contact compensation, fixture or
  contact limits).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from hoh_cosim.control.cycle import PROBE_SENSORS
from hoh_cosim.control.loadcell import R_SL_SEED, estimator_defaults
from hoh_cosim.kinds import KINDS
from hoh_cosim.yamlfile import Where

__all__ = ["with_probe_sensor"]


def _kind(name: str, spec: Any) -> Any:
    return spec.get("kind", name) if isinstance(spec, Mapping) else name


def _params(spec: Any) -> dict[str, Any]:
    params = spec.get("params") if isinstance(spec, Mapping) else None
    return dict(params) if isinstance(params, Mapping) else {}


def _with_params(spec: Any, params: dict[str, Any]) -> dict[str, Any]:
    return {**(dict(spec) if isinstance(spec, Mapping) else {}), "params": params}


def with_probe_sensor(raw: Mapping[str, Any], w: Where) -> dict[str, Any]:
    """The scenario's YAML (its `extends:` resolved) with its `probe_sensor` applied and removed."""
    raw = dict(raw)
    sensor = raw.pop("probe_sensor", "fse103")
    if not isinstance(sensor, str) or sensor not in PROBE_SENSORS:
        raise w.error("probe_sensor", f"expected one of {', '.join(PROBE_SENSORS)}, got {sensor!r}")
    components = raw.get("components")
    if sensor == "fse103" or not isinstance(components, Mapping):
        return raw
    probes = [n for n, c in components.items() if _kind(n, c) == "fse103"]
    if len(probes) != 1:
        raise w.error(
            "probe_sensor",
            f"{sensor} replaces the scenario's one fse103 component; it has {len(probes)}",
        )
    old = probes[0]
    new = "loadcell" if sensor == "loadcell" else None
    loadcell_spec = components.get("loadcell") if old != "loadcell" else None
    out: dict[str, Any] = {}
    for name, spec in components.items():
        if name == "loadcell" and name != old:
            continue  # the load cell's entry takes the FSE103's place below
        if name == old:
            if new is not None:
                spec = {**(dict(loadcell_spec) if isinstance(loadcell_spec, Mapping) else {})}
                spec["kind"] = "loadcell"
                out[new] = spec
            continue
        kind = _kind(name, spec)
        if kind == "plant" and new is not None:
            params = _params(spec)
            tool = dict(params.get("tool") or {})
            tool.setdefault("R_SP", R_SL_SEED.tolist())
            spec = _with_params(spec, {**params, "tool": tool})
        elif kind == "estimator":
            params = _params(spec)
            if new is None:
                params["use_probe"] = False
            else:
                rate = _params(loadcell_spec).get("rate_hz", KINDS["loadcell"].params().rate_hz)
                if isinstance(rate, (int, float)) and rate > 0:  # else the loader says so
                    params.setdefault("probe_packet_period_s", 1.0 / rate)
                params = estimator_defaults(params)
            spec = _with_params(spec, params)
        out[name] = spec
    raw["components"] = out
    raw["connections"] = _rewired(raw.get("connections"), old, new)
    if new is None:
        inputs = dict(raw.get("inputs") or {})
        for name, spec in out.items():
            if _kind(name, spec) == "estimator":
                inputs.setdefault(f"{name}.force_P", [0.0, 0.0, 0.0])
                inputs.setdefault(f"{name}.probe_counter", 0.0)
        raw["inputs"] = inputs
    return raw


def _rewired(connections: Any, old: str, new: str | None) -> Any:
    """The connections with the component `old` renamed `new` (None: those touching it gone)."""
    if not isinstance(connections, list):
        return connections  # the loader says what is wrong with it
    out = []
    for item in connections:
        if not isinstance(item, Mapping):
            out.append(item)
            continue
        ends = {k: item.get(k) for k in ("from", "to")}
        touches = [k for k, v in ends.items() if isinstance(v, str) and v.startswith(f"{old}.")]
        if touches and new is None:
            continue
        item = dict(item)
        for k in touches:
            item[k] = new + item[k][len(old) :]  # type: ignore[operator]
        out.append(item)
    return out
