"""Presets: a named, documented, validated set of the estimator's and the controller's parameters,
and the session steps they need, chosen by one word.

A preset is a YAML file (the shipped ones beside this module; a user's anywhere):

    name: clinical                       # the shipped ones: the file's stem
    description: >-                      # one line: what it is for
      The best for scanning a breathing patient ...
    extends: glide                       # optional: a shipped preset's name, or a file's path
                                         # (from this file); mappings merge key by key
    session:
      probe_check_s: 20.0                # the probe check at the session's start (0: none)
    estimator: {filter: kalman, ...}     # EstimatorParams, as a scenario's params
    controller: {hold: {enabled: true}}  # ControllerParams

A preset changes only what it names; the blocks' own defaults give the rest. Where it is applied
(`hoh_cosim.cosim.scenario`, `hoh_cosim.hardware.config`, `hoh_cosim.cosim.export`, the clinical
study) the order is: the blocks' defaults, the preset, the file's own parameters (a scenario's
component params, a rig's estimator and controller sections: the experiment and the rig), then
`--set`. The probe check is the estimator's (`probe_correction.kind` online for `check_s`); in a
co-simulation the simulated hand also pushes the probe's tip for that long before its task
(`plant_models.operator`), and the task starts and the run ends that much later.

Every mistake is one line naming the file and the key: an unknown preset lists the known ones.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hoh_cosim.errors import ConfigError
from hoh_cosim.params import from_mapping, leaves
from hoh_cosim.yamlfile import Where, read_yaml

if TYPE_CHECKING:
    from hoh_cosim.control.controller import ControllerParams
    from hoh_cosim.control.estimator import EstimatorParams

__all__ = [
    "BLOCKS",
    "DEFAULT_PRESET",
    "FIGURES",
    "PRESETS_DIR",
    "Preset",
    "changed_from",
    "figure_lines",
    "load_figures",
    "load_preset",
    "preset_names",
]

PRESETS_DIR = Path(__file__).resolve().parent
"""Where the shipped presets are."""

DEFAULT_PRESET = "seed"
"""The preset of a scenario that names none, of `hw run` and of the clinical study's runs without
`--preset`: the seed's law, until the `clinical` preset meets the clinical targets on populations
nobody tuned on (docs/decisions)."""


class _Blocks(Mapping[str, type]):
    """The blocks' names, and their parameter classes imported on first use: the command line's
    parser names the presets without loading the controller and its compiled kernels."""

    _NAMES = ("estimator", "controller")

    def __getitem__(self, name: str) -> type:
        if name not in self._NAMES:
            raise KeyError(name)
        return _block_classes()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._NAMES)

    def __len__(self) -> int:
        return len(self._NAMES)


@functools.cache
def _block_classes() -> dict[str, type]:
    from hoh_cosim.control.controller import ControllerParams
    from hoh_cosim.control.estimator import EstimatorParams

    return {"estimator": EstimatorParams, "controller": ControllerParams}


BLOCKS: Mapping[str, type] = _Blocks()
"""The blocks a preset sets, by the name of their kind and section, and their parameters."""

FIGURES = PRESETS_DIR / "figures.json"
"""The presets' measured figures, written by `hoh-cosim study clinical --figures` (its command
and seeds under `_measured_by`)."""

_KEYS = ("name", "description", "extends", "session", *BLOCKS)
_SESSION_KEYS = ("probe_check_s",)


@dataclass(frozen=True)
class Preset:
    """A preset, resolved and checked: its parameters for each block in `BLOCKS` (`params`) and
    the session steps."""

    name: str
    description: str
    path: Path
    params: Mapping[str, Any]  # "estimator" -> EstimatorParams, "controller" -> ControllerParams
    probe_check_s: float = 0.0  # [s] the probe check at the session's start (0: none)

    @property
    def estimator(self) -> EstimatorParams:
        return self.params["estimator"]

    @property
    def controller(self) -> ControllerParams:
        return self.params["controller"]

    @property
    def shipped(self) -> bool:
        return self.path.parent == PRESETS_DIR

    @property
    def label(self) -> str:
        """The preset's name, or its file's path for a user's own."""
        return self.name if self.shipped else str(self.path)

    def changes(self) -> dict[str, Any]:
        """What the preset sets that differs from the blocks' defaults, as `block.leaf` names."""
        return {
            f"{block}.{name}": value
            for block, params in self.params.items()
            for name, value in changed_from(BLOCKS[block](), params).items()
        }


def changed_from(base: Any, params: Any) -> dict[str, Any]:
    """The leaves of `params` (`hoh_cosim.params.leaves`) whose values differ from `base`'s."""
    before = {leaf.name: leaf.value for leaf in leaves(base)}
    return {leaf.name: leaf.value for leaf in leaves(params) if before.get(leaf.name) != leaf.value}


def preset_names() -> list[str]:
    """The shipped presets' names, in the order `hoh-cosim presets` lists them."""
    names = sorted(path.stem for path in PRESETS_DIR.glob("*.yaml"))
    return sorted(names, key=lambda n: (n not in _ORDER, _ORDER.index(n) if n in _ORDER else 0, n))


_ORDER = ("seed", "transparent", "checked", "hold", "follow", "glide", "clinical")


def load_preset(name: str | Path) -> Preset:
    """A shipped preset by its name, or a preset file by its path (one ending in .yaml or holding
    a path separator); every mistake is one line naming the file and the key."""
    return _load(str(name))


@functools.lru_cache(maxsize=32)
def _load(name: str) -> Preset:
    path = _path_of(name)
    raw = _resolved(path, ())
    w = Where(path)
    params = {}
    for block, cls in BLOCKS.items():
        try:
            params[block] = from_mapping(cls(), raw.get(block) or {}, block)
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None
    session = w.mapping(raw.get("session") or {}, _SESSION_KEYS, "session")
    check = w.number(session.get("probe_check_s", 0.0), "session.probe_check_s")
    if check < 0.0:
        raise w.error("session.probe_check_s", f"expected a number >= 0, got {check!r}")
    stem = path.stem
    name = raw.get("name", stem)
    if not isinstance(name, str) or not name:
        raise w.error("name", f"expected a non-empty string, got {name!r}")
    if path.parent == PRESETS_DIR and name != stem:
        raise w.error("name", f"expected {stem!r} (the file's name), got {name!r}")
    description = raw.get("description", "")
    if not isinstance(description, str) or not description.strip():
        raise w.error("description", f"expected one line of text, got {description!r}")
    if check > 0.0:
        params["estimator"] = _with_probe_check(params["estimator"], check, w)
    return Preset(name, " ".join(description.split()), path, params, check)


def _path_of(name: str) -> Path:
    if name.endswith((".yaml", ".yml")) or "/" in name:
        path = Path(name)
        if not path.is_file():
            raise ConfigError(f"preset {name!r}: no such preset file")
        return path.resolve()
    path = PRESETS_DIR / f"{name}.yaml"
    if not path.is_file():
        raise ConfigError(
            f"preset {name!r}: unknown (presets: {', '.join(preset_names())}; or the path of a "
            "preset file)"
        )
    return path


def _resolved(path: Path, seen: tuple[Path, ...]) -> dict[str, Any]:
    """The file's document with its `extends:` chain merged in (the base checked first)."""
    w = Where(path)
    raw = read_yaml(path)
    raw = dict(w.mapping(raw if raw is not None else {}, _KEYS, ""))
    for block in BLOCKS:
        if block in raw and raw[block] is not None and not isinstance(raw[block], Mapping):
            raise w.error(block, f"expected a mapping of parameters, got {raw[block]!r}")
    base_name = raw.pop("extends", None)
    if base_name is None:
        return raw
    if not isinstance(base_name, str) or not base_name:
        raise w.error("extends", f"expected a preset's name or a file's path, got {base_name!r}")
    if base_name.endswith((".yaml", ".yml")) or "/" in base_name:
        base = (path.parent / base_name).resolve()
        if not base.is_file():
            raise w.error("extends", f"no such preset file '{base_name}' (looked for {base})")
    else:
        base = PRESETS_DIR / f"{base_name}.yaml"
        if not base.is_file():
            raise w.error(
                "extends", f"unknown preset {base_name!r} (presets: {', '.join(preset_names())})"
            )
    if base in seen or base == path:
        raise w.error("extends", f"'{base_name}' extends this file again (a cycle)")
    _load(str(base))  # a mistake in the base is reported against the base
    merged = _merge(_resolved(base, (*seen, path)), raw)
    for key in ("name", "description"):  # the preset's own, never its base's
        merged.pop(key, None)
        if key in raw:
            merged[key] = raw[key]
    return merged


def _merge(base: Any, change: Any) -> Any:
    if isinstance(base, Mapping) and isinstance(change, Mapping):
        out = dict(base)
        for key, value in change.items():
            out[key] = _merge(base[key], value) if key in base else value
        return out
    return change


def _with_probe_check(estimator: EstimatorParams, check_s: float, w: Where) -> EstimatorParams:
    """The estimator identifying the probe sensor's map from the pushes of the check
    (`hoh_cosim.control.probe_correction`, the online map)."""
    correction = estimator.probe_correction
    try:
        return dataclasses.replace(
            estimator,
            probe_correction=dataclasses.replace(correction, kind="online", check_s=check_s),
        )
    except ConfigError as exc:
        raise w.error("session.probe_check_s", str(exc)) from None


def load_figures() -> dict[str, Any]:
    """The presets' measured figures (`FIGURES`), {} before any were measured."""
    import json

    if not FIGURES.is_file():
        return {}
    return json.loads(FIGURES.read_text(encoding="utf-8"))


def figure_lines(figures: Mapping[str, Any] | None) -> list[str]:
    """A preset's measured figures as a few lines of text (none if not measured)."""
    if not figures:
        return []
    lines = []
    effort = figures.get("hand_force_reduction_pct_min") or {}
    jitter = figures.get("jitter_improvement_pct_mean") or {}
    if effort:
        lines.append(
            "hand force less than freehand, every operator: "
            + ", ".join(f"{task} {value:.0f} %" for task, value in effort.items())
        )
    if jitter:
        lines.append(
            "image jitter better than freehand, on average: "
            + ", ".join(f"{task} {value:+.0f} %" for task, value in jitter.items())
        )
    hold, losses = figures.get("hold_contact_force_std_N_max"), figures.get("hold_contact_losses")
    if hold is not None:
        lines.append(f"hands-off contact force std at most {hold:.2f} N, {losses or 0:.0f} losses")
    back, peak = figures.get("recovery_time_s_max"), figures.get("recovery_peak_N_max")
    never = figures.get("recovery_never_back") or 0
    if never:
        lines.append(f"after the patient moved away the contact never came back in {never} runs")
    elif back is not None:
        lines.append(f"contact back within {back:.2f} s of a loss, at most {peak:.1f} N")
    drift, settle = figures.get("release_drift_mm"), figures.get("release_settle_ms")
    if drift is not None:
        settled = "never settled" if settle is None else f"settled in {settle:.0f} ms"
        lines.append(f"release: {drift:.2f} mm of drift, {settled}")
    return lines
