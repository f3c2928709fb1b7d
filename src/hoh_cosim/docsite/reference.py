"""The documentation's reference pages, generated from the code so that they cannot drift from it.

Each function returns one page's Markdown: every command and option (the argument parsers
themselves), every parameter of every block (its unit, default and the range its validation
accepts), every FMU's variables (`hoh_cosim.fmi.docs`), every metric
(`hoh_cosim.cosim.metric_reference`), the status bits and the modes, the scenario file format and
the session log's schemas. The site's build hook (`docs/hooks.py`) calls `pages()`.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import math
import pkgutil
import re
from collections.abc import Iterator

from hoh_cosim import cli
from hoh_cosim.control.guidance.modes import TRANSITIONS, Event, Mode
from hoh_cosim.control.supervisor import LATCHED_FLAGS, STOP_FLAGS, Status
from hoh_cosim.cosim import scenario as scenario_module
from hoh_cosim.cosim.metric_reference import METRICS
from hoh_cosim.cosim.scenario import METRIC_SETS
from hoh_cosim.errors import ConfigError
from hoh_cosim.fmi import docs as fmu_docs
from hoh_cosim.hardware import session_log
from hoh_cosim.kinds import KINDS
from hoh_cosim.params import Leaf, leaves, with_values
from hoh_cosim.presets import preset_names

__all__ = ["accepted_range", "pages"]

_GENERATED = "Generated from the code by `docs/hooks.py` at every build of this site."


def pages() -> dict[str, str]:
    """Site path -> Markdown of every generated reference page."""
    return {
        "reference/cli.md": cli_page(),
        "reference/parameters.md": parameters_page(),
        "reference/fmus.md": fmus_page(),
        "reference/metrics.md": metrics_page(),
        "reference/status-and-modes.md": status_page(),
        "reference/scenario-format.md": scenario_page(),
        "reference/session-log.md": session_log_page(),
        **api_pages(),
    }


API_PACKAGES = {
    "control": "hoh_cosim.control",
    "cosim": "hoh_cosim.cosim",
    "fmi": "hoh_cosim.fmi",
    "hardware": "hoh_cosim.hardware",
    "rehearsal": "hoh_cosim.rehearsal",
    "study": "hoh_cosim.study",
    "presets": "hoh_cosim.presets",
    "plant_models": "plant_models",
}
"""API page -> the package whose modules it documents from their docstrings (mkdocstrings)."""


def api_pages() -> dict[str, str]:
    out = {}
    for page, package in API_PACKAGES.items():
        module = importlib.import_module(package)
        names = sorted(
            info.name
            for info in pkgutil.walk_packages(module.__path__, f"{package}.")
            if not info.name.rsplit(".", 1)[-1].startswith("_")
        )
        lines = [f"# `{package}`", "", _GENERATED + " From the modules' docstrings.", ""]
        lines += [f"::: {package}", "    options:", "      members: false", ""]
        for name in names:
            lines += [f"::: {name}", ""]
        out[f"reference/api/{page}.md"] = "\n".join(lines)
    return out


# --- commands -------------------------------------------------------------------------------------


def _subcommands(parser: argparse.ArgumentParser) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def _walk(
    parser: argparse.ArgumentParser, path: tuple[str, ...]
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    yield path, parser
    for name, child in _subcommands(parser):
        yield from _walk(child, (*path, name))


def cli_page() -> str:
    lines = [
        "# Commands",
        "",
        _GENERATED,
        "Each section is the command's own `--help`.",
        "",
        "Exit status of every command: 0 done; 2 the input is wrong (one line naming the file, the "
        "key or the option, nothing run); 1 the run failed (one line with the cause); 130 "
        "interrupted.",
        "",
    ]
    for path, parser in _walk(cli._main_parser(), ("hoh-cosim",)):
        lines += [f"## `{' '.join(path)}`", "", "```text", parser.format_help().rstrip(), "```", ""]
    return "\n".join(lines)


# --- parameters -----------------------------------------------------------------------------------

_REAL_TRIES = (-1e6, -1.0, -1e-9, 0.0, 1e-9, 0.5, 1.0, 1.0 + 1e-9, 2.0, 1e6)
_INT_TRIES = (-1, 0, 1, 2, 1_000_000)
_CHOICES = re.compile(r"expected one of (?P<choices>[^;]+?)(?:, got|$)")


def _accepts(params: object, leaf: Leaf, value: object) -> bool:
    try:
        with_values(params, {leaf.name: value})
    except (ConfigError, ValueError, TypeError):
        return False
    return True


def accepted_range(params: object, leaf: Leaf) -> str:
    """The values `leaf` may take, found by asking the parameters' own validation (with every
    other parameter at its default): "any", "≥ 0", "> 0", "≥ 0, ≤ 1", "one of a, b", ...

    A number's bounds are bracketed by a grid of tries, then found by bisection to 6 digits."""
    if leaf.kind == "boolean":
        return "true, false"
    if leaf.kind == "string":
        try:
            with_values(params, {leaf.name: "\x00not-a-choice"})
        except ConfigError as exc:
            match = _CHOICES.search(str(exc))
            return f"one of {match['choices']}" if match else "text"
        return "text"
    tries = _REAL_TRIES if leaf.kind == "real" else _INT_TRIES
    ok = {x: _accepts(params, leaf, x) for x in tries}
    if all(ok.values()):
        return "any"
    accepted = [x for x in tries if ok[x]]
    if not accepted:
        return "see the block's docstring"
    if [x for x in tries if not ok[x]] == [0]:
        return "≠ 0"
    lo, hi = tries.index(min(accepted)), tries.index(max(accepted))
    if not all(ok[x] for x in tries[lo : hi + 1]):
        return "see the block's docstring"  # not one interval on these tries
    integer = leaf.kind == "integer"
    lower = "" if lo == 0 else _edge(params, leaf, tries[lo], tries[lo - 1], ">", integer)
    upper = (
        "" if hi == len(tries) - 1 else _edge(params, leaf, tries[hi], tries[hi + 1], "<", integer)
    )
    if lower and upper and lower.split()[-1] == upper.split()[-1]:  # one value: tied to others
        base = leaf.name.rpartition("[")[0]
        return f"with the rest of `{base}` (set it whole)" if base else f"= {lower.split()[-1]}"
    return ", ".join(bound for bound in (lower, upper) if bound)


def _edge(
    params: object, leaf: Leaf, inside: float, outside: float, side: str, integer: bool
) -> str:
    """The bound between an accepted and a rejected value, by bisection: "≥ 0", "> 0", "≤ 180"."""
    if integer:
        while abs(outside - inside) > 1:
            middle = (inside + outside) // 2
            inside, outside = (
                (middle, outside) if _accepts(params, leaf, middle) else (inside, middle)
            )
        return f"{side}= {int(inside)}".replace(">=", "≥").replace("<=", "≤")
    for _ in range(80):
        middle = 0.5 * (inside + outside)
        if middle in (inside, outside) or abs(outside - inside) <= 1e-8 * max(1.0, abs(inside)):
            break
        inside, outside = (middle, outside) if _accepts(params, leaf, middle) else (inside, middle)
    edge = float(f"{inside:.6g}")
    if abs(edge) < 1e-6:  # the tries bracket 0 by 1e-9: a bound at 0
        edge = 0.0
    closed = _accepts(params, leaf, edge)
    return f"{side}{'=' if closed else ''} {_number(edge)}".replace(">=", "≥").replace("<=", "≤")


def _number(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    if isinstance(value, str):
        return f'"{value}"'
    return str(value)


def parameters_page() -> str:
    lines = [
        "# Parameters",
        "",
        _GENERATED,
        "",
        "Every parameter of every block, by the name a scenario's `params:`, `--set "
        "component.name=value` and a preset use (vector elements numbered from 1). *default* is "
        "the block's own (a preset or a scenario may change it: `hoh-cosim presets NAME` shows "
        "what each preset sets); *range* is what the block's validation accepts with every other "
        "parameter at its default, found by trying values; *tunable* ones may change during a "
        "run (a scenario's `events:`).",
        "",
        f"Presets: {', '.join(f'`{name}`' for name in preset_names())}.",
        "",
    ]
    for kind in KINDS.values():
        params = kind.params()
        lines += [
            f"## `{kind.name}`",
            "",
            f"{kind.description[0].upper()}{kind.description[1:]} "
            f"(`{kind.block.__module__}.{kind.block.__name__}`, parameters "
            f"`{kind.params.__name__}`).",
            "",
            "| parameter | default | unit | range | tunable |",
            "|---|---|---|---|---|",
        ]
        lines += [
            f"| `{leaf.name}` | {_number(leaf.value)} | {leaf.unit or ''} | "
            f"{accepted_range(params, leaf)} | {'yes' if leaf.tunable else ''} |"
            for leaf in leaves(params)
        ]
        lines.append("")
    return "\n".join(lines)


# --- FMUs, metrics, status ------------------------------------------------------------------------


def fmus_page() -> str:
    body = fmu_docs.fmus_readme()
    body = body.replace("# FMUs\n", "", 1).replace("\n## ", "\n## ", 1)
    return "\n".join(["# FMUs", "", _GENERATED + " The same text is `fmus/README.md`.", body])


def metrics_page() -> str:
    lines = [
        "# Metrics",
        "",
        _GENERATED,
        "",
        "What a run writes under `metrics` in its `summary.json` and prints. The scenario's "
        "`metrics:` key chooses the set; `src/hoh_cosim/cosim/report.py` and "
        "`src/hoh_cosim/cosim/clinical.py` compute them. A metric the run cannot give (too short, "
        "no contact) is `null` with a note. A list holds one value per axis x, y, z.",
        "",
        "Metric sets and the components each needs: "
        + "; ".join(f"`{name}`" for name in METRIC_SETS)
        + ".",
        "",
    ]
    sets: dict[str, list[str]] = {}
    for name, doc in METRICS.items():
        sets.setdefault(doc.metric_set, []).append(name)
    for metric_set, names in sets.items():
        lines += [f"## {metric_set}", "", "| metric | unit | definition |", "|---|---|---|"]
        lines += [
            f"| `{name}` | {METRICS[name].unit} | {METRICS[name].definition} |" for name in names
        ]
        lines.append("")
    return "\n".join(lines)


def _doc(obj: object) -> str:
    return inspect.cleandoc(obj.__doc__ or "")


def status_page() -> str:
    lines = [
        "# Status bits and modes",
        "",
        _GENERATED,
        "",
        "## Status bits",
        "",
        "The controller's `status` output (and the session log's `/command` `status`) is a bit "
        "field; results write it decoded beside it (`controller.status_text`). A *stop* bit makes "
        "the command zero; a *latched* one stays until a reset (`src/hoh_cosim/control/"
        "supervisor.py`).",
        "",
        "| flag | value | stops | latched | meaning |",
        "|---|---|---|---|---|",
    ]
    for flag in Status:
        lines.append(
            f"| `{flag.name}` | {int(flag)} | {'yes' if flag & STOP_FLAGS else ''} | "
            f"{'yes' if flag & LATCHED_FLAGS else ''} | {Status(flag).describe()} |"
        )
    lines += [
        "",
        "## Modes",
        "",
        "The controller's `mode` output, one value per tick (`src/hoh_cosim/control/guidance/"
        "modes.py`):",
        "",
        "| mode | value | as a sonographer says it |",
        "|---|---|---|",
    ]
    lines += [f"| `{mode.name}` | {int(mode)} | {mode.label} |" for mode in Mode]
    lines += [
        "",
        "## Transitions",
        "",
        "The one table of the mode machine: in *mode*, *event* leads to *next*. A pair not listed "
        "keeps the mode.",
        "",
        "| mode | event | next |",
        "|---|---|---|",
    ]
    lines += [
        f"| `{mode.name}` | {event.value} | `{after.name}` |"
        for (mode, event), after in TRANSITIONS.items()
    ]
    lines += ["", "Events:", ""]
    lines += [f"- `{event.name}` ({event.value})" for event in Event]
    return "\n".join(lines) + "\n"


# --- scenario format and session log -------------------------------------------------------------


def scenario_page() -> str:
    doc = _doc(scenario_module)
    title, _, body = doc.partition("\n\n")
    lines = [
        "# Scenario files",
        "",
        _GENERATED,
        "",
        title,
        "",
        "```yaml",
        inspect.cleandoc(body.split("\n\n")[0]),
        "```",
        "",
        "\n\n".join(body.split("\n\n")[1:]),
        "",
        "## Component kinds",
        "",
        "A component's `kind` (default: its name); each kind's parameters are in "
        "[Parameters](parameters.md), its ports in [FMUs](fmus.md).",
        "",
        "| kind | what |",
        "|---|---|",
    ]
    lines += [f"| `{kind.name}` | {kind.description} |" for kind in KINDS.values()]
    lines += [
        "",
        "## Metric sets",
        "",
        "A scenario's `metrics:` names one; each needs these components (one of a group).",
        "",
        "| metrics | components |",
        "|---|---|",
    ]
    for name, needs in METRIC_SETS.items():
        parts = [" or ".join(need) if isinstance(need, tuple) else need for need in needs]
        lines.append(f"| `{name}` | {', '.join(parts) or '(none)'} |")
    return "\n".join(lines) + "\n"


def session_log_page() -> str:
    doc = _doc(session_log)
    lines = [
        "# The session log",
        "",
        _GENERATED,
        "",
        _indented_blocks(doc),
        "",
        "## Channels",
        "",
    ]
    for topic, fields in session_log.CHANNELS.items():
        lines += [
            f"### `{topic}`",
            "",
            "| field | JSON type | size | decimals |",
            "|---|---|---|---|",
        ]
        for name, kind in fields.items():
            size = kind.get("maxItems", 1)
            decimals = session_log.RESOLUTION.get((topic, name), "")
            lines.append(f"| `{name}` | {kind['type']} | {size} | {decimals} |")
        schema = json.dumps(session_log.channel_schema(topic), indent=2)
        lines += ["", '??? note "JSON schema"', "", "    ```json"]
        lines += [f"    {row}" for row in schema.splitlines()]
        lines += ["    ```", ""]
    return "\n".join(lines)


def _indented_blocks(doc: str) -> str:
    """A docstring's indented blocks as fenced text blocks, for Markdown."""
    out: list[str] = []
    block: list[str] = []
    for line in [*doc.splitlines(), ""]:
        if line.startswith("    "):
            block.append(line[4:])
            continue
        if block:
            out += ["```text", *block, "```"]
            block = []
        out.append(line)
    return "\n".join(out)
