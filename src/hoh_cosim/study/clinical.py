"""`hoh-cosim study clinical`: freehand against assisted scanning, a population of sonographers on
a breathing patient: the user study the seed could not run (000, 1.A, 5.D).

    for each operator i of N (plant_models.population: hand, tremor, strength, grip; their patient's
                          breathing), seeded [S, i]: the same person and patient in every run
      for each task       view     reach a view 5 cm away and hold it 60 s at 10 N (15 s --quick)
                          scan     a 10 cm line across the breathing abdomen at 8 N, 1 cm/s
                          press    press to 15 N and hold
                          recover  hold a view at 10 N; the patient moves 15 mm away in 0.3 s
        for each mode     freehand, and one assisted mode per preset (`STUDY_PRESETS`, or
                          --preset): the preset's estimator and controller (hoh_cosim.presets),
                          then the study's `--set` (`study_modes`); a preset that holds the
                          contact lets the hand go in contact (`Task.let_go`)
          one run         scenarios/clinical_freehand.yaml or clinical_assisted.yaml under the
                          mode's preset with the operator's, the task's and the patient's
                          overrides, the clinical metric set (hoh_cosim.cosim.clinical)
      per assisted mode   scenarios/release.yaml: the drift and settling after a release

All runs go to Dask as the sweeps' do (`hoh_cosim.study.sweep.run_variants`). Per task and
assisted mode, each operator's run is paired with their freehand run: the hand force's reduction
100 (1 - F_assisted / F_freehand) (RMS, peak, impulse) and the image-plane jitter's improvement
100 (1 - J_assisted / J_freehand), their mean with a 95 % confidence interval (Student's t over
operators) and the smallest over operators; the force stability (contact force std, contact
losses), the task time, the path error and the contact's recovery side by side with the mean
paired difference; each assisted mode against the targets (`TARGETS`).

DIR gets `index.html` and `report.md` (tables, the figures beside them), `runs.csv` and
`runs.parquet` (every run: operator, task, mode, status and every metric), `operators.csv` (every
operator's and patient's draw) and `summary.json`:

    {"tasks": {task: {mode: {"hand_force_reduction_pct": {"mean", "min", "max", "ci95", "n",
                                                          "per_operator"},
                             "jitter_improvement_pct": {...}, ...}}}, "fang_2017": ...,
     "presets": {mode: {"preset", "description", "changes"}}, "hold_on_release": ...,
     "release": ..., "targets": {mode: ...}, "overrides": [the --set texts], ...}

With `--figures FILE` the presets' headline figures go to FILE as `hoh-cosim presets` reads them
(`hoh_cosim.presets.FIGURES`). The directory is replaced whole and only when everything is
written; a mistake in the options is one line and nothing written.
"""

from __future__ import annotations

import csv
import io
import json
import math
import textwrap
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.cosim.clinical import JITTER_HZ
from hoh_cosim.errors import ConfigError
from hoh_cosim.study.sweep import (
    Outcome,
    Variant,
    check_scheduler,
    run_variants,
    set_option,
    table_rows,
)
from hoh_cosim.study.verification import Section, Table, page_html, page_markdown

__all__ = [
    "ASSISTED",
    "FANG_2017",
    "FREEHAND",
    "MODES",
    "STUDY_PRESETS",
    "TARGETS",
    "TASKS",
    "ClinicalResult",
    "Mode",
    "Task",
    "paired_change",
    "preset_figures",
    "run_clinical",
    "study_modes",
    "study_variants",
    "write_preset_figures",
]

FULL_OPERATORS = 20
QUICK_OPERATORS = 3
MAX_OPERATORS = 1000
FREEHAND = "freehand"

FANG_2017 = {
    "hand_force_reduction_pct": (32.0, 73.0),
    "image_stability_improvement_pct": (8.0, 18.0),
}
"""Fang, Zhang, Finocchi, Taylor and Boctor 2017 (the seed's [6]), "Force-assisted ultrasound
imaging system through dual force sensing and admittance robot control", IJCARS 12(6):983-991:
the same UR5 and dual sensing, a user study of expert sonographers and lay people: "32-73 %
reduction in human applied force and 8-18 % improvement in image stability" against freehand."""

TARGETS = {
    # at least, for every operator (the smallest over the operators), per task
    "hand_force_reduction_pct": {"view": 75.0, "scan": 75.0, "press": 60.0},
    "jitter_improvement_pct": 20.0,  # at least, the mean over the operators, on every task above
    "hold_contact_force_std_N": 0.5,  # at most, in every hold (hands off), with no contact loss
    "release_drift_m": 0.5e-3,  # at most, on scenarios/release.yaml
    "release_settle_s": 0.05,  # at most, on scenarios/release.yaml
    "recovery_time_s": 2.0,  # at most, every operator's run of the recover task
    "recovery_peak_N": 20.0,  # at most, ... and the contact force never above it
}
"""The clinical preset's targets for the full study (at least 20 operators; issue 51)."""
JITTER_TASKS = ("view", "scan", "press")
"""The tasks of the effort and jitter targets: the scanning itself (the recover task is the
patient moving away, which the hand and the robot answer, not a scan)."""


@dataclass(frozen=True)
class Task:
    """One clinical task: the operator's parameters and how long the hand works at it."""

    name: str
    label: str
    operator: tuple[tuple[str, Any], ...]  # OperatorParams fields
    task_s: float  # from the hand taking the probe to the end of the run
    quick_task_s: float
    # in the modes that let go (hold-on-release): when the hand lets go of the handle and takes it
    # again, after the task's start, and any more operator parameters then (the next view); full
    # study and --quick. None: this task's hand never lets go; a retake past the run's end: never
    hand_off: tuple[float, float] | None = None
    quick_hand_off: tuple[float, float] | None = None
    after_retake: tuple[tuple[str, Any], ...] = ()  # the retake's time + these, as offsets
    # the patient: BreathingParams fields; the run's times among them (`_PATIENT_TIMES`) after the
    # task's start
    patient: tuple[tuple[str, Any], ...] = ()

    def duration(self, quick: bool) -> float:
        return self.quick_task_s if quick else self.task_s

    def let_go(self, quick: bool) -> tuple[str, ...]:
        """The operator's overrides that make the hand let go in contact and take the handle
        again (`plant_models.operator`: let_go_s, retake_s)."""
        times = self.quick_hand_off if quick else self.hand_off
        if times is None:
            return ()
        let_go, retake = times
        out = [set_option("operator.let_go_s", let_go), set_option("operator.retake_s", retake)]
        out += [set_option(f"operator.{k}", retake + v) for k, v in self.after_retake]
        return tuple(out)

    def breathing(self, start_s: float) -> tuple[str, ...]:
        """The patient's overrides for a task that starts at `start_s`."""
        return tuple(
            set_option(f"breathing.{k}", start_s + v if k in _PATIENT_TIMES else v)
            for k, v in self.patient
        )


_PATIENT_TIMES = ("away_s",)
"""The patient's parameters that are times on the run's clock (the others are durations)."""


AWAY_M = 0.015
"""[m] The recover task's planted contact loss: the patient moves this far away ..."""
AWAY_TIME_S = 0.3
"""[s] ... within this long (issue 51)."""

TASKS: dict[str, Task] = {
    t.name: t
    for t in (
        Task(
            "view",
            "reach a view 5 cm away and hold it at 10 N",
            (
                ("task", "view"),
                ("target_force_N", 10.0),
                ("length_m", 0.05),
                ("reach_s", 5.0),
                ("direction_B", [1.0, 0.0, 0.0]),
            ),
            task_s=68.0,  # the approach (about 3 s), the reach (5 s), 60 s held
            quick_task_s=23.0,  # 15 s held
            # letting go: 35 s of the 60 held hands-off (7 to 12 breaths), then on to the next
            # view 2 cm further (the touch that hands back); --quick: 6 s (a breath or two)
            hand_off=(15.0, 50.0),
            quick_hand_off=(10.0, 16.0),
            after_retake=(("next_s", 1.0),),
        ),
        Task(
            "scan",
            "a 10 cm scan line across the breathing abdomen at 8 N",
            (
                ("task", "scan"),
                ("target_force_N", 8.0),
                ("length_m", 0.10),
                ("period_s", 20.0),  # 10 s a pass, 1 cm/s
                ("direction_B", [1.0, 0.0, 0.0]),
            ),
            task_s=24.0,  # there and back
            quick_task_s=14.0,  # there
        ),
        Task(
            "press",
            "press to 15 N and hold",
            (("task", "press"), ("target_force_N", 15.0)),
            task_s=20.0,
            quick_task_s=10.0,
            # letting go once the force is reached: 8 s hands-off (--quick: 4 s), then the hand's
            # press loop again; a scan is never let go of mid-line
            hand_off=(8.0, 16.0),
            quick_hand_off=(5.0, 9.0),
        ),
        Task(
            "recover",
            "hold a view at 10 N; the patient moves 15 mm away within 0.3 s",
            (
                ("task", "view"),
                ("target_force_N", 10.0),
                ("length_m", 0.02),
                ("reach_s", 3.0),
                ("direction_B", [1.0, 0.0, 0.0]),
            ),
            task_s=18.0,  # the approach and the reach (about 6 s), held, the move at 12 s
            quick_task_s=18.0,
            # in the modes that let go, the hand is off before the patient moves and stays off:
            # the robot alone brings the contact back (the others: the hand, as freehand)
            hand_off=(8.0, 1000.0),
            quick_hand_off=(8.0, 1000.0),
            patient=(("away_s", 12.0), ("away_m", AWAY_M), ("away_time_s", AWAY_TIME_S)),
        ),
    )
}
"""The study's tasks, defined once."""

FREEHAND_PRESS = (("force_kp", 0.5), ("force_ki", 2.0))
"""The press loop of a hand holding the probe itself. On the robot the contact force answers the
hand's push through the admittance's integration (about 1100 N/m · 0.0125 m/(s·N) = 14 /s), so the
operator's default loop (0.2 and 0.2 /s) crosses over at about 2.8 rad/s; freehand the force answers
the push at once, and the same loop would take 6 s to settle. A person keeps the bandwidth, not the
gains: 0.5 and 2 /s cross over at about 2.3 rad/s with the 150 ms delay's phase margin intact, and
are the only thing a mode changes in the hand (docs/decisions)."""

STUDY_PRESETS = ("seed", "transparent", "checked", "hold", "follow", "glide", "clinical")
"""The presets the study runs as its assisted modes unless `--preset` names others
(`hoh_cosim.presets`: each mode is one preset, the law set there)."""


@dataclass(frozen=True)
class Mode:
    """How the probe is held: freehand, or by the robot under a preset (`hoh_cosim.presets`) in
    the assisted scenario."""

    name: str
    label: str
    scenario: str  # in the scenarios directory
    preset: str | None = None  # the estimator's and the controller's (assisted); a name or a file
    operator: tuple[tuple[str, Any], ...] = ()  # the hand's parameters in this mode
    lets_go: bool = False  # the hand lets go in contact and takes the handle again (Task.let_go)
    overrides: tuple[str, ...] = ()  # the study's --set, after the preset (assisted modes)

    @property
    def assisted(self) -> bool:
        return self.preset is not None

    @property
    def arm(self) -> str:
        """The component that holds the probe, whose grip and signals the study uses."""
        return "plant" if self.assisted else "freehand"

    @property
    def grip(self) -> str:
        """Where the hand's grip is: on the handle (the operator) or in the freehand probe."""
        return "operator" if self.assisted else "freehand"

    def own(self) -> tuple[str, ...]:
        """The mode's own overrides: the hand's parameters, then the study's --set."""
        return (*(set_option(f"operator.{k}", v) for k, v in self.operator), *self.overrides)


def study_modes(
    presets: Sequence[str] = STUDY_PRESETS, overrides: Sequence[str] = ()
) -> dict[str, Mode]:
    """Freehand, then one assisted mode per preset (a name, or a preset file), each with
    `overrides` (the study's `--set`) after its preset, so that they win over it: a law, a gain or
    the hand's press loop tried on every assisted mode at once. Each operator's draw and each
    task's settings still come after them (`study_variants`): the population and the tasks stay
    the study's. Freehand stays as it is: the comparison is against the same hands holding the
    probe themselves. A mode lets go when its preset holds the contact (hold-on-release)."""
    from hoh_cosim.presets import load_preset

    modes = {
        FREEHAND: Mode(FREEHAND, "freehand", "clinical_freehand.yaml", operator=FREEHAND_PRESS)
    }
    for name in presets:
        preset = load_preset(name)
        if preset.name in modes:
            raise ConfigError(
                f"--preset {name}: a mode named {preset.name!r} is in the study already"
            )
        modes[preset.name] = Mode(
            preset.name,
            f"assisted, {preset.name}",
            "clinical_assisted.yaml",
            preset=name,
            lets_go=preset.controller.hold.enabled,
            overrides=tuple(overrides),
        )
    return modes


MODES = study_modes()
"""The study's modes with its default presets."""
ASSISTED = tuple(name for name, mode in MODES.items() if mode.assisted)


_KEEP_EVERY = 10  # the kept traces at 100 Hz


def _keep(mode: Mode) -> tuple[str, ...]:
    return (
        f"{mode.arm}.F_contact_B",
        "breathing.offset_m",
        "operator.F_hand_B",
    )


def _kept(mode: Mode, more: Sequence[str]) -> tuple[str, ...]:
    own = _keep(mode)
    return own + tuple(s for s in more if s not in own)


VIEWS = "views"
"""The study's folder of recordings, one a kept run (`--record-view`)."""


def _view_keep(scenarios: Path, modes: Mapping[str, Mode]) -> dict[str, tuple[str, ...]]:
    """Each mode's signals that its runs' views are made of (`hoh_cosim.view.cosim`)."""
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.view.cosim import view_signals

    return {
        name: view_signals(load_scenario(scenarios / mode.scenario, mode.own(), preset=mode.preset))
        for name, mode in modes.items()
    }


def _write_views(
    folder: Path,
    keyed: Sequence[tuple[tuple[int, str, str], Variant]],
    got: Mapping[tuple[int, str, str], Outcome],
    shared: Mapping[str, str],
) -> None:
    """One recording per kept run that ended well, `operator-01-view-freehand.rrd` (a mode that
    shares another's runs has that mode's)."""
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.view.cosim import record_signals

    folder.mkdir()
    for (i, task, name), variant in keyed:
        outcome = got.get((i, task, name))
        if name in shared or outcome is None or not outcome.ok or outcome.time is None:
            continue
        scenario = load_scenario(
            variant.scenario, variant.overrides, variant.duration_s, variant.seed, variant.preset
        )
        record_signals(
            scenario,
            outcome.time,
            outcome.signals,
            folder / f"operator-{i + 1:02d}-{task}-{name}.rrd",
            title=f"operator {i + 1}, {task}, {name}",
        )


def operator_seed(seed: int, index: int) -> int:
    """The scenario seed of operator `index`'s runs: every mode and task of one operator shares it,
    so their tremor and their patient's breathing are the same in every run."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0] & 0x7FFFFFFF)


def _operator_overrides(mode: Mode, index: int, seed: int) -> list[str]:
    from plant_models.population import RANGES, draw_operator, draw_patient

    hand = draw_operator(RANGES, seed, index)
    patient = draw_patient(RANGES, seed, index)
    out = [set_option(f"operator.{k}", v) for k, v in hand.operator_values().items()]
    out += [set_option(f"{mode.grip}.{k}", v) for k, v in hand.grip_values().items()]
    out += [set_option(f"breathing.{k}", v) for k, v in patient.breathing_values().items()]
    return out


def _start_s(scenarios: Path, mode: Mode) -> float:
    """When the hand takes the probe in `mode`'s runs (its preset's probe check comes first)."""
    from hoh_cosim.cosim.scenario import load_scenario

    scenario = load_scenario(scenarios / mode.scenario, mode.own(), preset=mode.preset)
    op = scenario.component_of_kind("operator")
    assert op is not None, "a clinical scenario has an operator"
    return float(op.params.start_s)


def study_variants(
    scenarios: Path,
    operators: int,
    seed: int,
    quick: bool,
    modes: Mapping[str, Mode] = MODES,
    view_keep: Mapping[str, tuple[str, ...]] | None = None,
) -> list[tuple[tuple[int, str, str], Variant]]:
    """((operator, task, mode), run) for every run of the study, each checked against its scenario
    first (so a mistake is one line before anything runs); `view_keep` (mode -> signals): what a
    kept run brings back besides its traces, for its view."""
    from hoh_cosim.cosim.scenario import load_scenario

    starts = {name: _start_s(scenarios, mode) for name, mode in modes.items()}
    out: list[tuple[tuple[int, str, str], Variant]] = []
    for i in range(operators):
        for task in TASKS.values():
            for name, mode in modes.items():
                overrides = (
                    *mode.own(),
                    *_operator_overrides(mode, i, seed),
                    *(set_option(f"operator.{k}", v) for k, v in task.operator),
                    *(task.let_go(quick) if mode.lets_go else ()),
                    # the patient starts breathing as the hand takes the probe: the same breaths
                    # meet the task at the same moments in every mode
                    set_option("breathing.start_s", starts[name]),
                    *task.breathing(starts[name]),
                )
                duration = starts[name] + task.duration(quick)
                path = scenarios / mode.scenario
                if i == 0:  # every operator's overrides set the same parameters
                    load_scenario(path, overrides, duration, preset=mode.preset)
                out.append(
                    (
                        (i, task.name, name),
                        Variant(
                            len(out),
                            str(path.resolve()),
                            overrides,
                            (("operator", i + 1), ("task", task.name), ("mode", name)),
                            operator_seed(seed, i),
                            duration,
                            "inprocess",
                            _kept(mode, (view_keep or {}).get(name, ())) if i < 3 else (),
                            _KEEP_EVERY,
                            preset=mode.preset,
                        ),
                    )
                )
    return out


def _ci95(values: Sequence[float]) -> tuple[float, float] | None:
    """The mean's 95 % confidence interval (Student's t), None for fewer than two values."""
    n = len(values)
    if n < 2:
        return None
    from scipy import stats

    mean = float(np.mean(values))
    half = float(stats.t.ppf(0.975, n - 1) * np.std(values, ddof=1) / math.sqrt(n))
    return mean - half, mean + half


def _stats(values: Sequence[float]) -> dict[str, Any]:
    if not values:
        return {"n": 0, "mean": None, "min": None, "max": None, "ci95": None, "per_operator": []}
    ci = _ci95(values)
    return {
        "n": len(values),
        "mean": float(np.mean(values)),
        "min": float(np.min(values)),
        "max": float(np.max(values)),
        "ci95": None if ci is None else list(ci),
        "per_operator": [float(v) for v in values],
    }


def paired_change(
    freehand: Sequence[float | None], assisted: Sequence[float | None]
) -> dict[str, Any]:
    """100 (1 - assisted / freehand) per operator where both exist and freehand is not zero, and
    its statistics (`_stats`): a reduction (or improvement) in per cent, negative when worse."""
    values = [
        100.0 * (1.0 - a / f)
        for f, a in zip(freehand, assisted, strict=True)
        if f is not None and a is not None and f != 0.0
    ]
    return _stats(values)


def _paired_difference(
    freehand: Sequence[float | None], assisted: Sequence[float | None]
) -> dict[str, Any]:
    both = [
        (f, a) for f, a in zip(freehand, assisted, strict=True) if f is not None and a is not None
    ]
    out = _stats([a - f for f, a in both])
    out["freehand_mean"] = float(np.mean([f for f, _ in both])) if both else None
    out["assisted_mean"] = float(np.mean([a for _, a in both])) if both else None
    return out


# -- the study ------------------------------------------------------------------------------------


@dataclass
class ClinicalResult:
    out: Path
    summary: dict[str, Any]
    outcomes: list[Outcome]
    sections: list[Section] = field(default_factory=list)


def _metric(outcome: Outcome | None, key: str) -> Any:
    if outcome is None or not outcome.ok:
        return None
    value = outcome.metrics.get(key)
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _check_options(operators: int, seed: int, scheduler: str | None, workers: int | None) -> None:
    if not 1 <= operators <= MAX_OPERATORS:
        raise ConfigError(
            f"--operators: expected an integer from 1 to {MAX_OPERATORS}, got {operators}"
        )
    if seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {seed}")
    if workers is not None and workers < 0:
        raise ConfigError(f"--workers: expected an integer >= 0, got {workers}")
    if scheduler is not None:
        check_scheduler(scheduler)


def _needed(scenarios: Path, modes: Mapping[str, Mode]) -> None:
    for mode in modes.values():
        if not (scenarios / mode.scenario).is_file():
            raise ConfigError(
                f"--scenarios {scenarios}: no {mode.scenario} there (run from a checkout of "
                "hoh-cosim, or pass --scenarios DIR)"
            )


def _parameters(scenarios: Path, mode: Mode) -> list[tuple[str, str, list[tuple[str, Any]]]]:
    """Every component of `mode`'s scenario under its preset and overrides: (name, kind, its
    parameters as (leaf, value) pairs), in the file's order."""
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.params import leaves

    s = load_scenario(scenarios / mode.scenario, mode.own(), preset=mode.preset)
    return [
        (name, c.kind.name, [(leaf.name, leaf.value) for leaf in leaves(c.params)])
        for name, c in s.components.items()
    ]


def _shared_modes(scenarios: Path, modes: Mapping[str, Mode]) -> dict[str, str]:
    """{mode: an earlier mode whose runs are the same}: the same scenario file, the same hand (it
    lets go or not) and every component's parameters equal, so that each of its runs, with the same
    operator, task and seed, is the earlier mode's run to the bit. Such runs are run once and
    reported under both modes."""
    shared: dict[str, str] = {}
    seen: list[tuple[str, tuple[Any, ...]]] = []
    for name, mode in modes.items():
        mine = (mode.scenario, mode.lets_go, _parameters(scenarios, mode))
        earlier = next((other for other, theirs in seen if theirs == mine), None)
        if earlier is None:
            seen.append((name, mine))
        else:
            shared[name] = earlier
    return shared


def _same_law(scenarios: Path, a: Mode, b: Mode) -> bool:
    """Whether two assisted modes give the controller and the estimator the same parameters."""

    def law(mode: Mode) -> list[tuple[str, list[tuple[str, Any]]]]:
        components = _parameters(scenarios, mode)
        return [
            next((kind, values) for _, k, values in components if k == kind)
            for kind in ("controller", "estimator")
        ]

    return law(a) == law(b)


def _assisted(modes: Mapping[str, Mode]) -> list[str]:
    return [name for name, mode in modes.items() if mode.assisted]


def run_clinical(
    out: str | Path,
    *,
    quick: bool = False,
    operators: int | None = None,
    seed: int = 1,
    workers: int | None = None,
    scheduler: str | None = None,
    scenarios: str | Path = "scenarios",
    progress: bool = True,
    overrides: Sequence[str] = (),
    presets: Sequence[str] | None = None,
    figures_out: str | Path | None = None,
    record_views: bool = False,
) -> ClinicalResult:
    """Run the study and write it to `out` (replaced whole): freehand and one assisted mode per
    preset (`presets`, default `STUDY_PRESETS`), `overrides` (`--set`) on every assisted mode
    (`study_modes`); with `figures_out`, the presets' measured figures as `hoh-cosim presets`
    shows them (`hoh_cosim.presets.FIGURES`); with `record_views`, one Rerun recording per kept
    run (the first three operators') in `out`/views/."""
    from hoh_cosim.cosim.run import jsonable
    from hoh_cosim.results import check_out_dir, check_writable, replace_dir
    from hoh_cosim.study.sweep import write_table

    out = Path(out)
    scenarios = Path(scenarios)
    n = operators if operators is not None else (QUICK_OPERATORS if quick else FULL_OPERATORS)
    _check_options(n, seed, scheduler, workers)
    check_out_dir(out, marker="operators.csv", what="clinical study")
    if figures_out is not None:
        check_writable(Path(figures_out).parent, "--figures")
    modes = study_modes(presets or STUDY_PRESETS, overrides)
    _needed(scenarios, modes)
    view_keep = None
    if record_views:
        from hoh_cosim.view import require_rerun

        require_rerun("--record-view")
        view_keep = _view_keep(scenarios, modes)
    started = time.perf_counter()
    keyed = study_variants(scenarios, n, seed, quick, modes, view_keep)
    _check_overrides(overrides, keyed, modes)
    shared = _shared_modes(scenarios, modes)
    todo = [(key, v) for key, v in keyed if key[2] not in shared]
    releases = _release_variants(scenarios, seed, modes)
    ran = run_variants(
        [v for _, v in todo] + [v for _, v in releases],
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        label="clinical",
    )
    got = {key: o for (key, _), o in zip(todo, ran, strict=False)}
    released = {name: o for (name, _), o in zip(releases, ran[len(todo) :], strict=True)}
    for key, variant in keyed:  # a shared mode's rows: the earlier mode's run, under its own name
        if key[2] in shared:
            got[key] = replace(got[(key[0], key[1], shared[key[2]])], variant=variant)
    outcomes = [got[key] for key, _ in keyed]
    assisted = _assisted(modes)
    equal_laws = [
        (a, b)
        for i, a in enumerate(assisted)
        for b in assisted[i + 1 :]
        if _same_law(scenarios, modes[a], modes[b])
    ]
    summary = _summary(got, released, modes, n, seed, quick, equal_laws)
    summary["wall_s"] = time.perf_counter() - started
    summary["overrides"] = list(overrides)
    figures = _figures(got, n, summary, modes)
    sections = _sections(summary, got, n, equal_laws, figures, modes)
    columns, rows = table_rows(outcomes)

    def fill(staging: Path) -> None:
        for name, data in figures.items():
            (staging / name).write_bytes(data)
        write_table(staging, columns, rows)
        (staging / "operators.csv").write_text(_operators_csv(n, seed), encoding="utf-8")
        (staging / "summary.json").write_text(
            json.dumps(jsonable(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )
        title, line = _header(summary)
        (staging / "index.html").write_text(
            page_html(title, line, sections, _CSS), encoding="utf-8"
        )
        (staging / "report.md").write_text(page_markdown(title, line, sections), encoding="utf-8")
        if record_views:
            _write_views(staging / VIEWS, keyed, got, shared)

    replace_dir(out, fill, what="clinical study")
    if figures_out is not None:
        write_preset_figures(Path(figures_out), summary)
    return ClinicalResult(out, summary, outcomes, sections)


RELEASE_SCENARIO = "release.yaml"
"""The release's drift and settling, per assisted mode: the hand's 5 N push let go (seed 5.C)."""


def _release_variants(
    scenarios: Path, seed: int, modes: Mapping[str, Mode]
) -> list[tuple[str, Variant]]:
    """One run of `RELEASE_SCENARIO` per assisted mode, with its preset and the study's --set."""
    path = scenarios / RELEASE_SCENARIO
    if not path.is_file():
        return []
    out = []
    for name, mode in modes.items():
        if mode.assisted:
            variant = Variant(
                len(out),
                str(path.resolve()),
                mode.overrides,
                (("mode", name),),
                seed,
                preset=mode.preset,
            )
            out.append((name, variant))
    return out


def _check_overrides(
    overrides: Sequence[str],
    keyed: Sequence[tuple[tuple[int, str, str], Variant]],
    modes: Mapping[str, Mode],
) -> None:
    """Refuse a `--set` of a parameter that the study itself sets after the mode's overrides (each
    operator's draw, the task's settings, the let-go, the breath's start): it would be overridden
    in every run without a word."""
    own: set[str] = set()
    for (_, _, name), variant in keyed:
        own.update(text.split("=", 1)[0] for text in variant.overrides[len(modes[name].own()) :])
    for text in overrides:
        key = text.split("=", 1)[0].strip()
        if key in own:
            raise ConfigError(
                f"--set {key}: the study sets it in every run (each operator's draw, the task or "
                "the breath); expected a parameter of the law, the sensors or the hand's press loop"
            )


def _operators_csv(n: int, seed: int) -> str:
    from dataclasses import asdict

    from plant_models.population import RANGES, draw_operator, draw_patient

    rows = []
    for i in range(n):
        hand = asdict(draw_operator(RANGES, seed, i))
        del hand["index"]
        patient = {f"breathing_{k}": v for k, v in asdict(draw_patient(RANGES, seed, i)).items()}
        rows.append({"operator": i + 1, **hand, **patient})
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def _summary(
    got: Mapping[tuple[int, str, str], Outcome],
    released: Mapping[str, Outcome],
    modes: Mapping[str, Mode],
    n: int,
    seed: int,
    quick: bool,
    equal_laws: Sequence[tuple[str, str]],
) -> dict[str, Any]:
    from hoh_cosim.presets import load_preset

    ops = range(n)
    tasks: dict[str, Any] = {}
    assisted = _assisted(modes)
    for task in TASKS:

        def values(mode: str, key: str, task: str = task) -> list[Any]:
            return [_metric(got.get((i, task, mode)), key) for i in ops]

        per_mode: dict[str, Any] = {
            FREEHAND: {key: _stats_of(values(FREEHAND, key)) for key in _MEANS},
        }
        for mode in assisted:
            entry: dict[str, Any] = {
                "hand_force_reduction_pct": paired_change(
                    values(FREEHAND, "hand_force_rms_N"), values(mode, "hand_force_rms_N")
                ),
                "hand_force_peak_reduction_pct": paired_change(
                    values(FREEHAND, "hand_force_peak_N"), values(mode, "hand_force_peak_N")
                ),
                "hand_impulse_reduction_pct": paired_change(
                    values(FREEHAND, "hand_impulse_N_s"), values(mode, "hand_impulse_N_s")
                ),
                "jitter_improvement_pct": paired_change(
                    values(FREEHAND, "jitter_image_mm"), values(mode, "jitter_image_mm")
                ),
                "rotation_jitter_improvement_pct": paired_change(
                    values(FREEHAND, "jitter_rotation_deg"), values(mode, "jitter_rotation_deg")
                ),
            }
            for key in ("contact_force_std_N", "task_time_s", "path_rms_error_m"):
                entry[f"{key}_difference"] = _paired_difference(
                    values(FREEHAND, key), values(mode, key)
                )
            entry.update({key: _stats_of(values(mode, key)) for key in _MEANS})
            flags = [f for f in values(mode, "controller_flags") if f is not None]
            entry["controller_flags"] = {f: flags.count(f) for f in sorted(set(flags))}
            per_mode[mode] = entry
        tasks[task] = per_mode
    # hold-on-release, per mode whose hand lets go and per task it lets go in: the force through
    # the breaths while the robot held with the hand off and how far from its value at the
    # release, the contact losses while it held, the tip's jump at the hand-backs
    hold: dict[str, Any] = {}
    for mode in assisted:
        if not modes[mode].lets_go:
            continue
        hold[mode] = {}
        for name, task in TASKS.items():
            if (task.quick_hand_off if quick else task.hand_off) is None or task.patient:
                continue  # (the recover task's hold ends with the patient's move: its own figures)

            def held(key: str, task: str = name, mode: str = mode) -> list[Any]:
                return [_metric(got.get((i, task, mode)), key) for i in ops]

            hold[mode][name] = {
                "contact_force_std_N": _stats_of(held("hold_contact_force_std_N")),
                "contact_force_change_N": _stats_of(held("hold_contact_force_change_N")),
                "contact_losses": _stats_of(held("hold_contact_losses")),
                "handback_jump_m": _stats_of(held("handback_jump_m")),
                "handback_unasked_m": _stats_of(held("handback_unasked_m")),
                "hold_s": _stats_of(held("hold_s")),
                "handbacks": _stats_of(held("handbacks")),
            }
    release = {
        mode: {
            "drift_m": _metric(released.get(mode), "release_drift_m"),
            "settle_s": _metric(released.get(mode), "release_settle_s"),
        }
        for mode in assisted
    }
    failed = [
        f"operator {i + 1}, {task}, {mode}: {o.error}"
        for (i, task, mode), o in got.items()
        if not o.ok
    ]
    failed += [f"{RELEASE_SCENARIO}, {mode}: {o.error}" for mode, o in released.items() if not o.ok]
    presets = {}
    for name, mode in modes.items():
        if mode.preset is not None:
            preset = load_preset(mode.preset)
            presets[name] = {
                "preset": preset.label,
                "description": preset.description,
                "changes": preset.changes(),
            }
    return {
        "quick": quick,
        "operators": n,
        "seed": seed,
        "runs": len(got) + len(released),
        "release_runs": len(released),
        "failed_runs": failed,
        "tasks_defined": {name: t.label for name, t in TASKS.items()},
        "task_s": {name: t.duration(quick) for name, t in TASKS.items()},
        "modes": {name: m.label for name, m in modes.items()},
        "presets": presets,
        "equal_laws": [list(pair) for pair in equal_laws],
        "tasks": tasks,
        "fang_2017": {k: list(v) for k, v in FANG_2017.items()},
        "hold_on_release": hold,
        "release": release,
        "targets": _targets(tasks, hold, release, assisted, n),
    }


_MEANS = (
    "hand_force_rms_N",
    "hand_force_peak_N",
    "hand_impulse_N_s",
    "contact_force_mean_N",
    "contact_force_std_N",
    "contact_losses",
    "jitter_image_mm",
    "jitter_axial_mm",
    "jitter_lateral_mm",
    "jitter_rotation_deg",
    "task_time_s",
    "path_rms_error_m",
    "recovery_time_s",
    "recovery_peak_N",
)


def _stats_of(values: Sequence[Any]) -> dict[str, Any]:
    present = [float(v) for v in values if v is not None]
    out = _stats(present)
    out["sd"] = float(np.std(present, ddof=1)) if len(present) > 1 else None
    out["missing"] = len(values) - len(present)
    return out


def _targets(
    tasks: Mapping[str, Any],
    hold: Mapping[str, Any],
    release: Mapping[str, Any],
    assisted: Sequence[str],
    n: int,
) -> dict[str, Any]:
    """Each assisted mode against the targets (`TARGETS`); each `met` is None for a short study
    (fewer than 20 operators: the targets are the full study's). A measure that could not be taken
    (a run failed, a contact never came back) fails its target."""
    out: dict[str, Any] = {}
    full = n >= FULL_OPERATORS

    def judged(ok: bool) -> bool | None:
        return ok if full else None

    for mode in assisted:
        effort = {
            task: tasks[task][mode]["hand_force_reduction_pct"]["min"]
            for task in TARGETS["hand_force_reduction_pct"]
        }
        effort_ok = all(
            v is not None and v >= TARGETS["hand_force_reduction_pct"][task]
            for task, v in effort.items()
        )
        jitter = {t: tasks[t][mode]["jitter_improvement_pct"]["mean"] for t in JITTER_TASKS}
        jitter_ok = all(
            v is not None and v >= TARGETS["jitter_improvement_pct"] for v in jitter.values()
        )
        entry: dict[str, Any] = {
            "hand_force_reduction_pct_smallest": effort,
            "hand_force_reduction_met": judged(effort_ok),
            "jitter_improvement_pct_mean": jitter,
            "jitter_improvement_met": judged(jitter_ok),
        }
        if mode in hold:
            stds = [h["contact_force_std_N"]["max"] for h in hold[mode].values()]
            losses = [h["contact_losses"]["max"] for h in hold[mode].values()]
            missing = sum(h["contact_force_std_N"]["missing"] for h in hold[mode].values())
            std = None if None in stds or not stds else max(stds)
            lost = None if None in losses or not losses else max(losses)
            entry["hold_contact_force_std_N_largest"] = std
            entry["hold_contact_losses_largest"] = lost
            entry["hold_met"] = judged(
                std is not None
                and std <= TARGETS["hold_contact_force_std_N"]
                and lost == 0
                and missing == 0
            )
        recover = tasks["recover"][mode]
        back, peak = recover["recovery_time_s"], recover["recovery_peak_N"]
        entry["recovery_time_s_largest"] = back["max"]
        entry["recovery_never_back"] = back["missing"]
        entry["recovery_peak_N_largest"] = peak["max"]
        entry["recovery_met"] = judged(
            back["missing"] == 0
            and back["max"] is not None
            and back["max"] <= TARGETS["recovery_time_s"]
            and peak["max"] is not None
            and peak["max"] <= TARGETS["recovery_peak_N"]
        )
        drift, settle = release[mode]["drift_m"], release[mode]["settle_s"]
        entry["release_met"] = (
            drift is not None
            and settle is not None
            and drift <= TARGETS["release_drift_m"]
            and settle <= TARGETS["release_settle_s"]
        )
        out[mode] = entry
    return out


def preset_figures(summary: Mapping[str, Any]) -> dict[str, Any]:
    """Each assisted mode's headline figures, by preset, as `hoh-cosim presets` shows them
    (`hoh_cosim.presets.figure_lines`)."""
    out: dict[str, Any] = {}
    for mode, targets in summary["targets"].items():
        entry: dict[str, Any] = {
            "hand_force_reduction_pct_min": targets["hand_force_reduction_pct_smallest"],
            "jitter_improvement_pct_mean": targets["jitter_improvement_pct_mean"],
            "recovery_time_s_max": targets["recovery_time_s_largest"],
            "recovery_never_back": targets["recovery_never_back"],
            "recovery_peak_N_max": targets["recovery_peak_N_largest"],
        }
        if "hold_contact_force_std_N_largest" in targets:
            entry["hold_contact_force_std_N_max"] = targets["hold_contact_force_std_N_largest"]
            entry["hold_contact_losses"] = targets["hold_contact_losses_largest"]
        release = summary["release"][mode]
        if release["drift_m"] is not None:
            entry["release_drift_mm"] = 1e3 * release["drift_m"]
            settle = release["settle_s"]
            entry["release_settle_ms"] = None if settle is None else 1e3 * settle
        out[summary["presets"][mode]["preset"]] = entry
    return out


def write_preset_figures(path: Path, summary: Mapping[str, Any]) -> None:
    """`preset_figures` to `path` (a JSON file, replaced), with what measured them."""
    from hoh_cosim.cosim.run import jsonable

    source = (
        f"hoh-cosim study clinical --operators {summary['operators']} --seed {summary['seed']}"
        + (" --quick" if summary["quick"] else "")
    )
    data = {"_measured_by": source, **preset_figures(summary)}
    path.write_text(json.dumps(jsonable(data), indent=1) + "\n", encoding="utf-8")


# -- figures --------------------------------------------------------------------------------------

_COLOURS = {
    FREEHAND: "tab:red",
    "seed": "tab:blue",
    "transparent": "tab:orange",
    "checked": "tab:brown",
    "hold": "tab:purple",
    "follow": "tab:cyan",
    "glide": "tab:olive",
    "clinical": "tab:green",
}


def _panel_in(modes: Mapping[str, Mode]) -> float:
    """[in] A task's panel in the per-mode figures: room for each mode's wrapped label."""
    return max(3.0, 0.75 * len(modes))


def _colour(mode: str) -> str:
    return _COLOURS.get(mode, "tab:pink")


def _tick(modes: Mapping[str, Mode], mode: str) -> str:
    """A mode's label on an axis: without "assisted, " (every robot mode is), wrapped to fit the
    width a mode has in a task's panel (`_panel_in`)."""
    label = modes[mode].label.removeprefix("assisted, ")
    return textwrap.fill(label, 12, break_on_hyphens=False, break_long_words=False)


def _figures(
    got: Mapping[tuple[int, str, str], Outcome],
    n: int,
    summary: Mapping[str, Any],
    all_modes: Mapping[str, Mode],
) -> dict[str, bytes]:
    from hoh_cosim.cosim.plots import png, pyplot

    plt = pyplot()
    figures: dict[str, bytes] = {}
    modes = list(all_modes)
    assisted = _assisted(all_modes)
    labels = [_tick(all_modes, m) for m in modes]
    panel = _panel_in(all_modes)

    def by_operator(fig_name: str, key: str, scale: float, ylabel: str, title: str) -> None:
        fig, axes = plt.subplots(1, len(TASKS), figsize=(panel * len(TASKS), 4.2), squeeze=False)
        for ax, task in zip(axes[0], TASKS, strict=True):
            for i in range(n):
                ys = [_metric(got.get((i, task, m)), key) for m in modes]
                xs = [j for j, y in enumerate(ys) if y is not None]
                vals = [scale * ys[j] for j in xs]
                ax.plot(xs, vals, color="0.75", lw=0.8, zorder=1)
                for j, v in zip(xs, vals, strict=True):
                    ax.plot(j, v, "o", ms=4, color=_colour(modes[j]), zorder=2)
            ax.set_xticks(range(len(modes)), labels, fontsize=7)
            ax.set_xlim(-0.5, len(modes) - 0.5)
            ax.set_title(f"{task}: {TASKS[task].label}", fontsize=9)
            ax.grid(True, lw=0.4, color="0.9")
        axes[0, 0].set_ylabel(ylabel)
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        figures[fig_name] = png(fig)

    by_operator(
        "effort.png",
        "hand_force_rms_N",
        1.0,
        "hand force RMS [N]",
        "Effort: the hand's force on the probe, per operator (a grey line joins one operator's runs)",
    )
    by_operator(
        "jitter.png",
        "jitter_image_mm",
        1e3,
        "probe jitter in the image plane [µm RMS]",
        f"Image stability: the probe's motion above {JITTER_HZ:g} Hz in the image plane, per "
        "operator",
    )

    # reductions against Fang 2017 and the target
    fig, axes = plt.subplots(
        1, len(JITTER_TASKS), figsize=(panel * len(JITTER_TASKS), 4.2), squeeze=False
    )
    lo, hi = FANG_2017["hand_force_reduction_pct"]
    for ax, task in zip(axes[0], JITTER_TASKS, strict=True):
        ax.axhspan(lo, hi, color="0.9", label="Fang 2017: 32-73 %")
        target = TARGETS["hand_force_reduction_pct"][task]
        ax.axhline(target, color="k", ls="--", lw=0.8, label="target")
        ax.axhline(0.0, color="0.5", lw=0.6)
        for j, mode in enumerate(assisted):
            s = summary["tasks"][task][mode]["hand_force_reduction_pct"]
            xs = np.full(len(s["per_operator"]), j) + np.linspace(
                -0.15, 0.15, len(s["per_operator"])
            )
            ax.plot(xs, s["per_operator"], "o", ms=4, color=_colour(mode), alpha=0.7)
            if s["mean"] is not None:
                err = None
                if s["ci95"] is not None:
                    err = [[s["mean"] - s["ci95"][0]], [s["ci95"][1] - s["mean"]]]
                ax.errorbar(j + 0.3, s["mean"], yerr=err, fmt="s", color="k", ms=5, capsize=4)
        ax.set_xticks(range(len(assisted)), [_tick(all_modes, m) for m in assisted], fontsize=7)
        ax.set_xlim(-0.6, len(assisted) - 0.4)
        ax.set_title(task, fontsize=9)
        ax.grid(True, lw=0.4, color="0.9")
    axes[0, 0].set_ylabel("hand force RMS, less than freehand [%]")
    axes[0, 0].legend(fontsize=7, loc="lower left")
    fig.suptitle(
        "Effort saved against freehand, per operator (dots), mean and 95 % CI (black)", fontsize=10
    )
    fig.tight_layout()
    figures["reduction.png"] = png(fig)

    # force through breaths: operator 1, every task, every mode, on the task's clock
    from plant_models.operator import OperatorParams

    press = OperatorParams().press_direction_B
    fig, axes = plt.subplots(len(TASKS), 1, figsize=(10, 2.6 * len(TASKS)), squeeze=False)
    for ax, task in zip(axes[:, 0], TASKS, strict=True):
        breathing = None
        for mode in modes:
            o = got.get((0, task, mode))
            if o is None or not o.ok or not o.signals:
                continue
            t = o.time - (o.time[-1] - summary["task_s"][task])  # from the hand taking the probe
            sel = t >= summary["task_s"][task] - 12.0  # the last 12 s
            contact = -o.signals[f"{all_modes[mode].arm}.F_contact_B"][sel] @ press
            ax.plot(t[sel], contact, lw=1.0, color=_colour(mode), label=all_modes[mode].label)
            breathing = (t[sel], 1e3 * o.signals["breathing.offset_m"][sel, 0])
        if breathing is not None:
            twin = ax.twinx()
            twin.plot(*breathing, color="0.6", lw=0.8, ls=":")
            twin.set_ylabel("breathing [mm] (dotted)", fontsize=8, color="0.4")
        ax.axhline(dict(TASKS[task].operator)["target_force_N"], color="k", ls="--", lw=0.6)
        ax.set_ylabel("contact force [N]", fontsize=8)
        ax.set_title(f"{task}: operator 1, the last 12 s (dashed: the target)", fontsize=9)
        ax.grid(True, lw=0.4, color="0.9")
    axes[-1, 0].set_xlabel("time since the hand took the probe [s]")
    fig.suptitle(
        "The contact force (along the probe, pressing) through the patient's breaths, every mode",
        fontsize=10,
    )
    # the modes' labels under the panels, in rows, so that the panels keep the figure's width
    handles, names = axes[0, 0].get_legend_handles_labels()
    columns = 3
    fig.legend(handles, names, loc="lower center", ncol=columns, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0.0, 0.025 * math.ceil(len(names) / columns), 1.0, 1.0))
    figures["breath.png"] = png(fig)
    return figures


# -- the page -------------------------------------------------------------------------------------


def _f(value: Any, fmt: str = ".3g", scale: float = 1.0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return format(value * scale, fmt)


def _ci(s: Mapping[str, Any], fmt: str = ".0f") -> str:
    if s["mean"] is None:
        return "n/a"
    if s["ci95"] is None:
        return _f(s["mean"], fmt)
    return f"{_f(s['mean'], fmt)} [{_f(s['ci95'][0], fmt)}, {_f(s['ci95'][1], fmt)}]"


def _range_of(s: Mapping[str, Any], fmt: str = ".0f", scale: float = 1.0) -> str:
    if s["min"] is None:
        return "n/a"
    return f"{_f(s['min'], fmt, scale)} to {_f(s['max'], fmt, scale)}"


def _sections(
    summary: Mapping[str, Any],
    got: Mapping[tuple[int, str, str], Outcome],
    n: int,
    equal_laws: Sequence[tuple[str, str]],
    figures: Mapping[str, bytes],
    modes: Mapping[str, Mode],
) -> list[Section]:
    tasks = summary["tasks"]
    assisted = _assisted(modes)
    intro = Section("What ran")
    intro.text.append(
        f"{n} simulated sonographers (plant_models/population.py: hand stiffness and damping, "
        "reaction delay, physiological tremor, strength and grip drawn from the literature's "
        "ranges, with a patient each whose breathing is drawn too: 12-20 breaths a minute, "
        f"5-15 mm), seed {summary['seed']}, each doing every task in every mode: "
        + "; ".join(f"{name}: {t.label}" for name, t in TASKS.items())
        + ". Modes: freehand, and one per preset (hoh_cosim.presets): "
        + "; ".join(f"{name}: {entry['description']}" for name, entry in summary["presets"].items())
        + ". Each operator's assisted runs are compared with their own freehand run of the same "
        "task, on the same breathing patient, with the same tremor."
    )
    letting_go = [name for name in assisted if modes[name].lets_go]
    if letting_go:
        intro.text.append(
            "In the modes that hold the contact ("
            + ", ".join(letting_go)
            + ") the hand lets go in contact and takes the handle again ("
            + ", ".join(
                f"{name} from {t[0]:g} s to {t[1]:g} s after the start"
                for name, task in TASKS.items()
                if (t := (task.quick_hand_off if summary["quick"] else task.hand_off)) is not None
                and not task.patient
            )
            + "; on the view it then moves on to the next view, the touch that hands back; on "
            "the recover task it lets go for good before the patient moves away): its effort "
            "counts the time the robot held alone, as a sonographer's would."
        )
    for a, b in equal_laws:
        intro.text.append(
            f"'{modes[a].label}' and '{modes[b].label}' give the controller and the estimator the "
            "same parameters, so their numbers are the same (each such run is run once and "
            "reported under both)."
        )
    if summary["quick"] or n < FULL_OPERATORS:
        intro.text.append(
            f"A short study ({n} operators"
            + (", shorter tasks" if summary["quick"] else "")
            + "): the targets are the full study's (at least 20 operators), so they are not judged."
        )

    fang = Section("Fang 2017 beside ours")
    rows = []
    for task in JITTER_TASKS:
        for mode in assisted:
            e = tasks[task][mode]
            rows.append(
                [
                    task,
                    modes[mode].label,
                    "32 to 73",
                    f"{_range_of(e['hand_force_reduction_pct'])} (mean "
                    f"{_ci(e['hand_force_reduction_pct'])})",
                    "8 to 18",
                    f"{_range_of(e['jitter_improvement_pct'])} (mean "
                    f"{_ci(e['jitter_improvement_pct'])})",
                ]
            )
    fang.text.append(
        "Fang et al. 2017 (the seed's [6], same robot and dual sensing) measured, against "
        "freehand, 32-73 % less force applied by the operator and 8-18 % better image stability. "
        "Ours per operator (smallest to largest) and the mean with its 95 % confidence interval; "
        "the image-stability proxy is the probe's jitter in the image plane."
    )
    fang.tables.append(
        Table(
            "assisted against freehand, same operator and task [%]",
            [
                "task",
                "mode",
                "force, Fang 2017",
                "hand force RMS less, ours",
                "image stability, Fang 2017",
                "jitter less, ours",
            ],
            rows,
        )
    )

    targets = Section("Targets")
    targets.text.append(
        "The clinical preset's targets, for every preset: hand force less than freehand for "
        "every operator ("
        + ", ".join(f"{t} {v:g} %" for t, v in TARGETS["hand_force_reduction_pct"].items())
        + f"), image-plane jitter at least {TARGETS['jitter_improvement_pct']:g} % better on "
        f"average on every task ({', '.join(JITTER_TASKS)}), the contact force's std at most "
        f"{TARGETS['hold_contact_force_std_N']:g} N with no contact loss in every hold (hands "
        f"off), the contact back within {TARGETS['recovery_time_s']:g} s and never above "
        f"{TARGETS['recovery_peak_N']:g} N after the patient moved away, on every operator's "
        f"recover run, and on {RELEASE_SCENARIO} a drift of at most "
        f"{1e3 * TARGETS['release_drift_m']:g} mm and settled within "
        f"{1e3 * TARGETS['release_settle_s']:g} ms."
    )

    def met(flag: bool | None) -> str:
        return "not judged (short study)" if flag is None else ("met" if flag else "not met")

    rows = []
    for mode in assisted:
        t = summary["targets"][mode]
        rel = summary["release"][mode]
        rows.append(
            [
                modes[mode].label,
                ", ".join(
                    f"{task} {_f(v, '.0f')}"
                    for task, v in t["hand_force_reduction_pct_smallest"].items()
                )
                + f" % ({met(t['hand_force_reduction_met'])})",
                ", ".join(
                    f"{task} {_f(v, '+.0f')}"
                    for task, v in t["jitter_improvement_pct_mean"].items()
                )
                + f" % ({met(t['jitter_improvement_met'])})",
                "n/a"
                if "hold_met" not in t
                else f"{_f(t['hold_contact_force_std_N_largest'], '.2f')} N, "
                f"{_f(t['hold_contact_losses_largest'], '.0f')} losses ({met(t['hold_met'])})",
                f"{_f(t['recovery_time_s_largest'], '.2f')} s"
                + (f", {t['recovery_never_back']} never back" if t["recovery_never_back"] else "")
                + f", {_f(t['recovery_peak_N_largest'], '.1f')} N ({met(t['recovery_met'])})",
                f"{_f(rel['drift_m'], '.2f', 1e3)} mm, "
                + (
                    "never settled"
                    if rel["settle_s"] is None and rel["drift_m"] is not None
                    else f"{_f(rel['settle_s'], '.0f', 1e3)} ms"
                )
                + f" ({'met' if t['release_met'] else 'not met'})",
            ]
        )
    targets.tables.append(
        Table(
            "the targets",
            [
                "mode",
                "hand force less, smallest",
                "jitter better, mean",
                "hold: contact force std (largest), losses",
                "recovery: time (largest), force (largest)",
                f"release ({RELEASE_SCENARIO}): drift, settling",
            ],
            rows,
        )
    )
    for mode, per_task in summary["hold_on_release"].items():
        hold_rows = [
            [
                task,
                _range_of(e["contact_force_std_N"], ".2f"),
                _range_of(e["contact_force_change_N"], "+.2f"),
                _f(sum(e["contact_losses"]["per_operator"]), ".0f"),
                _range_of(e["handback_jump_m"], ".2f", 1e3),
                _range_of(e["handback_unasked_m"], ".2f", 1e3),
                _range_of(e["hold_s"], ".1f"),
                _f(sum(e["handbacks"]["per_operator"]), ".0f"),
            ]
            for task, e in per_task.items()
        ]
        targets.tables.append(
            Table(
                f"hold-on-release in '{modes[mode].label}', per operator (smallest to largest)",
                [
                    "task",
                    "contact force std, hands off [N]",
                    "hands-off force less the force at the release [N]",
                    "contact losses while held (all)",
                    "hand-back tip travel in the blend [mm]",
                    "of it not asked by the hand, across [mm]",
                    "held [s]",
                    "hand-backs (all)",
                ],
                hold_rows,
            )
        )

    out = [intro, fang, targets]
    for task in TASKS:
        sec = Section(f"Task: {task}, {TASKS[task].label}")
        rows = []
        for mode in modes:
            e = tasks[task][mode]
            assisted = mode != FREEHAND

            def mean_sd(key: str, fmt: str = ".2f", scale: float = 1.0, e: Any = e) -> str:
                s = e[key]
                if s["mean"] is None:
                    return "n/a"
                sd = "" if s["sd"] is None else f" ± {_f(s['sd'], fmt, scale)}"
                return f"{_f(s['mean'], fmt, scale)}{sd}"

            rows.append(
                [
                    modes[mode].label,
                    mean_sd("hand_force_rms_N"),
                    _ci(e["hand_force_reduction_pct"]) if assisted else "",
                    _f(e["hand_force_reduction_pct"]["min"], ".0f") if assisted else "",
                    mean_sd("hand_force_peak_N"),
                    mean_sd("hand_impulse_N_s", ".0f"),
                    mean_sd("contact_force_mean_N"),
                    mean_sd("contact_force_std_N"),
                    _f(sum(e["contact_losses"]["per_operator"]), ".0f"),
                    mean_sd("jitter_image_mm", ".1f", 1e3),
                    _ci(e["jitter_improvement_pct"]) if assisted else "",
                    mean_sd("jitter_rotation_deg", ".3f"),
                    mean_sd("task_time_s", ".1f"),
                    mean_sd("path_rms_error_m", ".1f", 1e3),
                    mean_sd("recovery_time_s", ".2f"),
                    mean_sd("recovery_peak_N", ".1f"),
                    ", ".join(f"{k} ({v})" for k, v in e.get("controller_flags", {}).items()),
                ]
            )
        sec.tables.append(
            Table(
                f"{task}: mean ± sd over operators; reductions paired per operator, mean [95 % CI]",
                [
                    "mode",
                    "hand force RMS [N]",
                    "less than freehand [%]",
                    "smallest [%]",
                    "peak [N]",
                    "impulse [N·s]",
                    "contact force [N]",
                    "contact force std [N]",
                    "contact losses (all)",
                    "jitter, image plane [µm]",
                    "better than freehand [%]",
                    "rotation jitter [°]",
                    "task time [s]",
                    "path error [mm]",
                    "contact back [s]",
                    "force after the move [N]",
                    "controller limits (runs)",
                ],
                rows,
            )
        )
        out.append(sec)

    figs = Section("Figures")
    captions = {
        "effort.png": "effort per operator and mode",
        "reduction.png": "hand force saved against freehand, with Fang 2017's range and the target",
        "breath.png": "the contact force through the patient's breaths, operator 1",
        "jitter.png": "image-plane jitter per operator and mode",
    }
    figs.figures += [(name, captions[name]) for name in captions if name in figures]
    out.append(figs)
    failed = summary["failed_runs"]
    if failed:
        sec = Section("Failed runs")
        sec.text += failed
        out.append(sec)
    return out


def _header(summary: Mapping[str, Any]) -> tuple[str, str]:
    kind = "quick" if summary["quick"] else "full"
    released = summary.get("release_runs", 0)
    line = (
        f"{summary['operators']} operators x {len(TASKS)} tasks x {len(summary['modes'])} modes = "
        f"{summary['runs'] - released} runs and {released} of {RELEASE_SCENARIO} "
        f"({kind}, seed {summary['seed']}), {summary['wall_s']:.0f} s"
    )
    if summary.get("overrides"):
        line += "; every assisted mode with " + " ".join(
            f"--set {text}" for text in summary["overrides"]
        )
    if summary["failed_runs"]:
        line += f"; {len(summary['failed_runs'])} failed"
    return "hoh-cosim clinical study: freehand against assisted scanning", line


_CSS = (
    "body{font-family:sans-serif;max-width:1200px;margin:2em auto;line-height:1.4}"
    "table{border-collapse:collapse;margin:1em 0;font-size:85%}"
    "td,th{border:1px solid #bbb;padding:3px 6px}caption{font-weight:bold;text-align:left}"
    "img{max-width:100%}"
)
