"""`hoh-cosim study clinical`: freehand against assisted scanning, a population of sonographers on
a breathing patient: the user study the seed could not run (000, 1.A, 5.D).

    for each operator i of N (plant_models.population: hand, tremor, strength, grip; their patient's
                          breathing), seeded [S, i]: the same person and patient in every run
      for each task       view   reach a view 5 cm away and hold it 60 s at 10 N (15 s with --quick)
                          scan   a 10 cm line across the breathing abdomen at 8 N, 1 cm/s
                          press  press to 15 N and hold
        for each mode     MODES: freehand, and each assisted law (one entry each); `--set`
                          overrides after each assisted mode's own (`with_overrides`)
          one run         scenarios/clinical_freehand.yaml or clinical_assisted.yaml with --set
                          overrides, the clinical metric set (hoh_cosim.cosim.clinical)

All runs go to Dask as the sweeps' do (`hoh_cosim.study.sweep.run_variants`). Per task and
assisted mode, each operator's run is paired with their freehand run: the hand force's reduction
100 (1 - F_assisted / F_freehand) (RMS, peak, impulse) and the image-plane jitter's improvement
100 (1 - J_assisted / J_freehand), their mean with a 95 % confidence interval (Student's t over
operators) and the smallest over operators; the force stability (contact force std, contact
losses), the task time and the path error side by side with the mean paired difference.

DIR gets `index.html` and `report.md` (tables, the figures beside them), `runs.csv` and
`runs.parquet` (every run: operator, task, mode, status and every metric), `operators.csv` (every
operator's and patient's draw) and `summary.json`:

    {"tasks": {task: {mode: {"hand_force_reduction_pct": {"mean", "min", "max", "ci95", "n",
                                                          "per_operator"},
                             "jitter_improvement_pct": {...}, ...}}}, "fang_2017": ...,
     "overrides": [the --set texts], ...}

The directory is replaced whole and only when everything is written; a mistake in the options is
one line and nothing written.
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
    "FANG_2017",
    "MODES",
    "TARGETS",
    "TASKS",
    "ClinicalResult",
    "Mode",
    "Task",
    "paired_change",
    "run_clinical",
    "study_variants",
    "with_overrides",
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
    "hand_force_reduction_pct": 75.0,  # at least, for every operator, on the view and scan tasks
    "jitter_improvement_pct": 20.0,  # at least, the mean
    "hold_contact_force_std_N": 0.5,  # at most, every operator, with no contact loss
    "handback_jump_m": 1e-3,  # at most, every operator
}
"""The issue's targets for the full study (at least 20 operators)."""
EFFORT_TASKS = ("view", "scan")
"""The tasks whose hand force the effort target is about (the issue: "the hold and scan tasks")."""


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
    # study and --quick. None: this task's hand never lets go
    hand_off: tuple[float, float] | None = None
    quick_hand_off: tuple[float, float] | None = None
    after_retake: tuple[tuple[str, Any], ...] = ()  # the retake's time + these, as offsets

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
    )
}
"""The study's tasks, defined once."""


def _seed_law() -> tuple[str, ...]:
    """The seed's law as `--set` overrides, pinned to the seed's own numbers (so that a change of
    the defaults leaves this mode as it was): eq. 10 with the seed's gains (3.F.1), contact
    compensation (eq. 11-12), no fixture, the Kalman filters (3.E) at the tuning that reproduces the
    seed's figures (4.C; `hoh_cosim.control.estimator.default_kalman`), our rotation gains (the
    seed gives none)."""
    from hoh_cosim.control.admittance import ROTATION_GAINS, TRANSLATION_GAINS
    from hoh_cosim.control.estimator import (
        FSE103_NOISE_MAX,
        FT150_NOISE_MAX_S,
        FT150_TORQUE_NOISE_MAX_S,
        default_kalman,
    )
    from hoh_cosim.params import leaves

    out = [
        "controller.contact_compensation=true",
        "controller.virtual_fixture=false",
        "estimator.filter=kalman",
    ]
    for prefix, value in (
        ("controller.translation", TRANSLATION_GAINS),
        ("controller.rotation", ROTATION_GAINS),
        ("estimator.hand_force_kalman", default_kalman(FT150_NOISE_MAX_S)),
        ("estimator.hand_torque_kalman", default_kalman(FT150_TORQUE_NOISE_MAX_S)),
        ("estimator.probe_force_kalman", default_kalman(FSE103_NOISE_MAX)),
    ):
        out += [set_option(f"{prefix}.{leaf.name}", leaf.value) for leaf in leaves(value)]
    return tuple(out)


FREEHAND_PRESS = ("operator.force_kp=0.5", "operator.force_ki=2.0")
"""The press loop of a hand holding the probe itself. On the robot the contact force answers the
hand's push through the admittance's integration (about 1100 N/m · 0.0125 m/(s·N) = 14 /s), so the
operator's default loop (0.2 and 0.2 /s) crosses over at about 2.8 rad/s; freehand the force answers
the push at once, and the same loop would take 6 s to settle. A person keeps the bandwidth, not the
gains: 0.5 and 2 /s cross over at about 2.3 rad/s with the 150 ms delay's phase margin intact, and
are the only thing a mode changes in the hand (docs/decisions.md)."""


TRANSPARENCY = (
    "estimator.filter=lead_lowpass",
    "controller.translation.law=variable",
    "controller.release.enabled=true",
    "controller.passivity.enabled=true",
)
"""The transparency issue's laws on today's defaults (docs/decisions.md, "Transparency past the
seed"): the lead-lag low-pass filter, the variable admittance, release detection with its brake,
the passivity observer and controller."""
PROBE_CHECK_S = 20.0
"""The probe check's length: ten pushes on the probe's tip, the online map's reference (as in
scenarios/contact_scan_online.yaml)."""
PROBE_CHECK = (
    set_option("operator.probe_check_s", PROBE_CHECK_S),
    # the task then, as clinical_assisted.yaml's 3 s after the rebias, after the check
    set_option("operator.start_s", 3.0 + PROBE_CHECK_S),
    "estimator.probe_correction.kind=online",
    set_option("estimator.probe_correction.check_s", PROBE_CHECK_S),
)
"""Today's defaults after a probe check (`hoh_cosim.control.probe_correction`, the online map): the
session begins with the hand off the handle and the robot still while the probe's tip is pushed
(`probe_check_s`), and the estimator maps the FSE103's housing of the day; the contact compensation
(eq. 11-12) then uses the corrected probe force. The FSE103's gain error (0.15 σ per axis, seed
3.B.2) is what kept the view's effort from 75 % less under the other laws (docs/decisions.md,
"The probe check in the clinical study")."""
HOLD_ON_RELEASE = (
    *PROBE_CHECK,
    "controller.release.enabled=true",
    "controller.hold.enabled=true",
    "controller.hold.force_source=wrist",
    # the probe checked, F̃ along the probe is right within a newton: a hand that went on pushing
    # or pulling while the robot held leaves its level when it is still (`retake_band_N`)
    "controller.hold.retake_band_N=1.0",
    # the probe rides the breath along the surface's normal, not sliding over the skin (`motion`),
    # and the contact's own swing is no touch (`swing_s`)
    "controller.hold.motion=normal",
    "controller.hold.swing_s=0.1",
)
"""Hold-on-release (`hoh_cosim.control.hold`) on today's defaults after a probe check, with the
release detection that tells it the hand let go, regulating the wrist sensor's force
(`force_source` wrist, as on the robot). The check comes first because the hold tells a hand on
the handle from none by F̃ along the probe, which the FSE103's gain error otherwise fills: without
it the hold engaged under a hand still pushing 1.4-5.2 N, and the contact fell by that push at
every let-go (docs/decisions.md, "The force the hold keeps"). With it, the hold also takes the
level a hand left by pushing on while held (the retake, 1 N band). It moves the probe along the
contact's mean direction, the surface's normal, rather than the probe's axis: on the abdomen's
flank the two differ by 12°, and the probe slid over the skin with every breath, friction turning
over along the axis at each breath's turn and driving the hold into a 12-16 Hz limit cycle
(docs/decisions.md, "The hold along the surface's normal"). The touch's band across the axis is
widened by the probe's own swing over the last 0.1 s, which the probe's filter lags: a hand
opening turned friction over and read as a touch. The combined force, better on
three operators' quick runs, was worse over the full study's twenty on every count but the press's
jitter: docs/decisions.md, "Hold-on-release"."""


FOLLOW_BREATH = (*PROBE_CHECK, "controller.follow.enabled=true")
"""Today's defaults after a probe check, the robot following the breath while the hand steers
(`hoh_cosim.control.follow`): in contact, the axial contact force's departure from its level over
about a breath moves the probe along its axis, so the hand no longer steers it up and down with
every breath (docs/decisions.md, "Following the breath while the hand steers")."""
GLIDE = (
    *FOLLOW_BREATH,
    "controller.glide.enabled=true",
    set_option("estimator.probe_correction.across_from_wrist_s", 5.0),
)
"""The follow mode with glide (`hoh_cosim.control.glide`): eq. 10 light for a steady push (3.2
times the slope under 0.5 Hz on the base's x and y, across the upright probe; the seed's slope
above), and a 0.3 N deadband there once the probe moves and while it glides, so that the hand
steering a scan pays less than the seed's 0.95 N and the image meets the seed's slope; along z in
contact, for a hand keeping the contact (a push under 1 N along it), a third of the seed's slope
above 0.5 Hz, so that the image moves less along the beam. The probe force across the probe takes
its part slower than 5 s from the wrist (`probe_correction.across_from_wrist_s`), so that the
hand does not hold the probe against the housing's play (docs/decisions.md, "Glide", "Glide
quieter along the probe in contact", "Glide keeps going" and "The play's error across the
probe")."""


@dataclass(frozen=True)
class Mode:
    """How the probe is held: freehand, or by the robot under a law (overrides of the assisted
    scenario). A new law is one more entry of `MODES`."""

    name: str
    label: str
    scenario: str  # in the scenarios directory
    overrides: tuple[str, ...] = ()
    assisted: bool = True
    lets_go: bool = False  # the hand lets go in contact and takes the handle again (Task.let_go)

    @property
    def arm(self) -> str:
        """The component that holds the probe, whose grip and signals the study uses."""
        return "plant" if self.assisted else "freehand"

    @property
    def grip(self) -> str:
        """Where the hand's grip is: on the handle (the operator) or in the freehand probe."""
        return "operator" if self.assisted else "freehand"


MODES: dict[str, Mode] = {
    m.name: m
    for m in (
        Mode(
            FREEHAND,
            "freehand",
            "clinical_freehand.yaml",
            FREEHAND_PRESS,
            assisted=False,
        ),
        Mode("seed", "assisted, the seed's law", "clinical_assisted.yaml", _seed_law()),
        Mode("defaults", "assisted, today's defaults", "clinical_assisted.yaml"),
        Mode(
            "checked",
            "assisted, today's defaults after a probe check",
            "clinical_assisted.yaml",
            PROBE_CHECK,
        ),
        Mode(
            "transparency",
            "assisted, the transparency laws",
            "clinical_assisted.yaml",
            TRANSPARENCY,
        ),
        Mode(
            "hold",
            "assisted, hold-on-release after a probe check",
            "clinical_assisted.yaml",
            HOLD_ON_RELEASE,
            lets_go=True,
        ),
        Mode(
            "follow",
            "assisted, following the breath after a probe check",
            "clinical_assisted.yaml",
            FOLLOW_BREATH,
        ),
        Mode(
            "glide",
            "assisted, gliding and following the breath after a probe check",
            "clinical_assisted.yaml",
            GLIDE,
        ),
    )
}
"""The study's modes, defined once."""
HOLD = "hold"
"""The mode whose hand lets go: the hold-on-release figures (`summary.json`'s `hold_on_release`)."""
ASSISTED = tuple(name for name, mode in MODES.items() if mode.assisted)


def with_overrides(overrides: Sequence[str]) -> dict[str, Mode]:
    """`MODES` with `overrides` (the study's `--set`) after each assisted mode's own, so that they
    win over the mode: a law, a gain or the hand's press loop tried on every assisted mode at once.
    Each operator's draw and each task's settings still come after them (`study_variants`): the
    population and the tasks stay the study's. Freehand stays as it is: the comparison is against
    the same hands holding the probe themselves."""
    extra = tuple(overrides)
    return {
        name: replace(mode, overrides=(*mode.overrides, *extra)) if mode.assisted else mode
        for name, mode in MODES.items()
    }


_KEEP_EVERY = 10  # the kept traces at 100 Hz


def _keep(mode: Mode) -> tuple[str, ...]:
    return (
        f"{mode.arm}.F_contact_B",
        "breathing.offset_m",
        "operator.F_hand_B",
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
    """When the hand takes the probe in `mode`'s runs (its overrides included: a probe check
    comes first)."""
    from hoh_cosim.cosim.scenario import load_scenario

    op = load_scenario(scenarios / mode.scenario, mode.overrides).component_of_kind("operator")
    assert op is not None, "a clinical scenario has an operator"
    return float(op.params.start_s)


def study_variants(
    scenarios: Path,
    operators: int,
    seed: int,
    quick: bool,
    modes: Mapping[str, Mode] = MODES,
) -> list[tuple[tuple[int, str, str], Variant]]:
    """((operator, task, mode), run) for every run of the study, each checked against its scenario
    first (so a mistake is one line before anything runs)."""
    from hoh_cosim.cosim.scenario import load_scenario

    starts = {name: _start_s(scenarios, mode) for name, mode in modes.items()}
    out: list[tuple[tuple[int, str, str], Variant]] = []
    for i in range(operators):
        for task in TASKS.values():
            for name, mode in modes.items():
                overrides = (
                    *mode.overrides,
                    *_operator_overrides(mode, i, seed),
                    *(set_option(f"operator.{k}", v) for k, v in task.operator),
                    *(task.let_go(quick) if mode.lets_go else ()),
                    # the patient starts breathing as the hand takes the probe: the same breaths
                    # meet the task at the same moments in every mode
                    set_option("breathing.start_s", starts[name]),
                )
                duration = starts[name] + task.duration(quick)
                path = scenarios / mode.scenario
                if i == 0:  # every operator's overrides set the same parameters
                    load_scenario(path, overrides, duration)
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
                            _keep(mode) if i < 3 else (),
                            _KEEP_EVERY,
                        ),
                    )
                )
    return out


# -- statistics -----------------------------------------------------------------------------------


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


def _needed(scenarios: Path) -> None:
    for mode in MODES.values():
        if not (scenarios / mode.scenario).is_file():
            raise ConfigError(
                f"--scenarios {scenarios}: no {mode.scenario} there (run from a checkout of "
                "hoh-cosim, or pass --scenarios DIR)"
            )


def _parameters(scenarios: Path, mode: Mode) -> list[tuple[str, str, list[tuple[str, Any]]]]:
    """Every component of `mode`'s scenario under its overrides: (name, kind, its parameters as
    (leaf, value) pairs), in the file's order."""
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.params import leaves

    s = load_scenario(scenarios / mode.scenario, mode.overrides)
    return [
        (name, c.kind.name, [(leaf.name, leaf.value) for leaf in leaves(c.params)])
        for name, c in s.components.items()
    ]


def _shared_modes(scenarios: Path, modes: Mapping[str, Mode] | None = None) -> dict[str, str]:
    """{mode: an earlier mode whose runs are the same}: the same scenario file, the same hand (it
    lets go or not) and every component's parameters equal, so that each of its runs, with the same
    operator, task and seed, is the earlier mode's run to the bit. Such runs are run once and
    reported under both modes."""
    shared: dict[str, str] = {}
    seen: list[tuple[str, tuple[Any, ...]]] = []
    for name, mode in (MODES if modes is None else modes).items():
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
) -> ClinicalResult:
    """Run the study and write it to `out` (replaced whole); `overrides` (`--set`) on every
    assisted mode (`with_overrides`)."""
    from hoh_cosim.cosim.run import jsonable
    from hoh_cosim.results import check_out_dir, replace_dir
    from hoh_cosim.study.sweep import write_table

    out = Path(out)
    scenarios = Path(scenarios)
    n = operators if operators is not None else (QUICK_OPERATORS if quick else FULL_OPERATORS)
    _check_options(n, seed, scheduler, workers)
    check_out_dir(out, marker="summary.json", what="clinical study")
    _needed(scenarios)
    started = time.perf_counter()
    modes = with_overrides(overrides)
    keyed = study_variants(scenarios, n, seed, quick, modes)
    _check_overrides(overrides, keyed, modes)
    shared = _shared_modes(scenarios, modes)
    todo = [(key, v) for key, v in keyed if key[2] not in shared]
    ran = run_variants(
        [v for _, v in todo],
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        label="clinical",
    )
    got = {key: o for (key, _), o in zip(todo, ran, strict=True)}
    for key, variant in keyed:  # a shared mode's rows: the earlier mode's run, under its own name
        if key[2] in shared:
            got[key] = replace(got[(key[0], key[1], shared[key[2]])], variant=variant)
    outcomes = [got[key] for key, _ in keyed]
    equal_laws = [
        (a, b)
        for i, a in enumerate(ASSISTED)
        for b in ASSISTED[i + 1 :]
        if _same_law(scenarios, modes[a], modes[b])
    ]
    summary = _summary(got, n, seed, quick, equal_laws, time.perf_counter() - started)
    summary["overrides"] = list(overrides)
    figures = _figures(got, n, summary)
    sections = _sections(summary, got, n, equal_laws, figures)
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

    replace_dir(out, fill)
    return ClinicalResult(out, summary, outcomes, sections)


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
        own.update(
            text.split("=", 1)[0] for text in variant.overrides[len(modes[name].overrides) :]
        )
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
    n: int,
    seed: int,
    quick: bool,
    equal_laws: Sequence[tuple[str, str]],
    wall_s: float,
) -> dict[str, Any]:
    ops = range(n)
    tasks: dict[str, Any] = {}
    for task in TASKS:

        def values(mode: str, key: str, task: str = task) -> list[Any]:
            return [_metric(got.get((i, task, mode)), key) for i in ops]

        per_mode: dict[str, Any] = {
            FREEHAND: {key: _stats_of(values(FREEHAND, key)) for key in _MEANS},
        }
        for mode in ASSISTED:
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
    # hold-on-release, per task whose hand lets go: the force through the breaths while the robot
    # held with the hand off and how far from its value at the release, the contact losses while
    # it held, the tip's jump at the hand-backs
    hold: dict[str, Any] = {}
    for name, task in TASKS.items():
        if (task.quick_hand_off if quick else task.hand_off) is None:
            continue

        def held(key: str, task: str = name) -> list[Any]:
            return [_metric(got.get((i, task, HOLD)), key) for i in ops]

        hold[name] = {
            "contact_force_std_N": _stats_of(held("hold_contact_force_std_N")),
            "contact_force_change_N": _stats_of(held("hold_contact_force_change_N")),
            "contact_losses": _stats_of(held("hold_contact_losses")),
            "handback_jump_m": _stats_of(held("handback_jump_m")),
            "handback_unasked_m": _stats_of(held("handback_unasked_m")),
            "hold_s": _stats_of(held("hold_s")),
            "handbacks": _stats_of(held("handbacks")),
        }
    failed = [
        f"operator {i + 1}, {task}, {mode}: {o.error}"
        for (i, task, mode), o in got.items()
        if not o.ok
    ]
    return {
        "quick": quick,
        "operators": n,
        "seed": seed,
        "runs": len(got),
        "failed_runs": failed,
        "wall_s": wall_s,
        "tasks_defined": {name: t.label for name, t in TASKS.items()},
        "task_s": {name: t.duration(quick) for name, t in TASKS.items()},
        "modes": {name: m.label for name, m in MODES.items()},
        "equal_laws": [list(pair) for pair in equal_laws],
        "tasks": tasks,
        "fang_2017": {k: list(v) for k, v in FANG_2017.items()},
        "hold_on_release": hold,
        "targets": _targets(tasks, hold, n),
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
)


def _stats_of(values: Sequence[Any]) -> dict[str, Any]:
    present = [float(v) for v in values if v is not None]
    out = _stats(present)
    out["sd"] = float(np.std(present, ddof=1)) if len(present) > 1 else None
    out["missing"] = len(values) - len(present)
    return out


def _targets(tasks: Mapping[str, Any], hold: Mapping[str, Any], n: int) -> dict[str, Any]:
    """Each assisted mode against the issue's targets, and hold-on-release against its own; `met`
    is None for a quick study (fewer than 20 operators: the targets are the full study's)."""
    out: dict[str, Any] = {}
    full = n >= FULL_OPERATORS
    stds = [h["contact_force_std_N"]["max"] for h in hold.values()]
    losses = [h["contact_losses"]["max"] for h in hold.values()]
    jumps = [h["handback_jump_m"]["max"] for h in hold.values() if h["handback_jump_m"]["n"]]
    std_max = None if not stds or None in stds else max(stds)
    loss_max = None if not losses or None in losses else max(losses)
    jump_max = max(jumps) if jumps else None
    out["hold_on_release"] = {
        "contact_force_std_N_largest": std_max,
        "contact_losses_largest": loss_max,
        "handback_jump_m_largest": jump_max,
        "met": (
            (
                std_max is not None
                and std_max <= TARGETS["hold_contact_force_std_N"]
                and loss_max == 0
                and jump_max is not None
                and jump_max <= TARGETS["handback_jump_m"]
            )
            if full
            else None
        ),
    }
    for mode in ASSISTED:
        effort = [tasks[t][mode]["hand_force_reduction_pct"] for t in EFFORT_TASKS]
        smallest = [e["min"] for e in effort]
        jitter = [tasks[t][mode]["jitter_improvement_pct"]["mean"] for t in TASKS]
        effort_ok = None not in smallest and min(smallest) >= TARGETS["hand_force_reduction_pct"]
        jitter_ok = None not in jitter and min(jitter) >= TARGETS["jitter_improvement_pct"]
        out[mode] = {
            "hand_force_reduction_pct_smallest": None if None in smallest else min(smallest),
            "hand_force_reduction_met": effort_ok if full else None,
            "jitter_improvement_pct_smallest_mean": None if None in jitter else min(jitter),
            "jitter_improvement_met": jitter_ok if full else None,
        }
    return out


# -- figures --------------------------------------------------------------------------------------

_COLOURS = {
    FREEHAND: "tab:red",
    "seed": "tab:blue",
    "defaults": "tab:green",
    "checked": "tab:brown",
    "transparency": "tab:orange",
    HOLD: "tab:purple",
    "follow": "tab:cyan",
    "glide": "tab:olive",
}


_PANEL_IN = 0.75 * len(MODES)
"""[in] A task's panel in the per-mode figures: room for each mode's wrapped label."""


def _colour(mode: str) -> str:
    return _COLOURS.get(mode, "tab:purple")


def _tick(mode: str) -> str:
    """A mode's label on an axis: without "assisted, " (every robot mode is), wrapped to fit the
    width a mode has in a task's panel (`_PANEL_IN`)."""
    label = MODES[mode].label.removeprefix("assisted, ")
    return textwrap.fill(label, 12, break_on_hyphens=False, break_long_words=False)


def _figures(
    got: Mapping[tuple[int, str, str], Outcome], n: int, summary: Mapping[str, Any]
) -> dict[str, bytes]:
    from hoh_cosim.cosim.plots import png, pyplot

    plt = pyplot()
    figures: dict[str, bytes] = {}
    modes = list(MODES)
    labels = [_tick(m) for m in modes]

    def by_operator(fig_name: str, key: str, scale: float, ylabel: str, title: str) -> None:
        fig, axes = plt.subplots(
            1, len(TASKS), figsize=(_PANEL_IN * len(TASKS), 4.2), squeeze=False
        )
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
    fig, axes = plt.subplots(1, len(TASKS), figsize=(_PANEL_IN * len(TASKS), 4.2), squeeze=False)
    lo, hi = FANG_2017["hand_force_reduction_pct"]
    for ax, task in zip(axes[0], TASKS, strict=True):
        ax.axhspan(lo, hi, color="0.9", label="Fang 2017: 32-73 %")
        ax.axhline(TARGETS["hand_force_reduction_pct"], color="k", ls="--", lw=0.8, label="target")
        ax.axhline(0.0, color="0.5", lw=0.6)
        for j, mode in enumerate(ASSISTED):
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
        ax.set_xticks(range(len(ASSISTED)), [_tick(m) for m in ASSISTED], fontsize=7)
        ax.set_xlim(-0.6, len(ASSISTED) - 0.4)
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
            contact = -o.signals[f"{MODES[mode].arm}.F_contact_B"][sel] @ press
            ax.plot(t[sel], contact, lw=1.0, color=_colour(mode), label=MODES[mode].label)
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
) -> list[Section]:
    tasks = summary["tasks"]
    intro = Section("What ran")
    intro.text.append(
        f"{n} simulated sonographers (plant_models/population.py: hand stiffness and damping, "
        "reaction delay, physiological tremor, strength and grip drawn from the literature's "
        "ranges, with a patient each whose breathing is drawn too: 12-20 breaths a minute, "
        f"5-15 mm), seed {summary['seed']}, each doing every task in every mode: "
        + "; ".join(f"{name}: {t.label}" for name, t in TASKS.items())
        + ". Modes: "
        + "; ".join(f"{name}: {m.label}" for name, m in MODES.items())
        + ". Each operator's assisted runs are compared with their own freehand run of the same "
        "task, on the same breathing patient, with the same tremor."
    )
    intro.text.append(
        "In the hold-on-release mode the hand lets go in contact and takes the handle again "
        "(holding a view: "
        + ", ".join(
            f"{name} from {t[0]:g} s to {t[1]:g} s after the start"
            for name, task in TASKS.items()
            if (t := (task.quick_hand_off if summary["quick"] else task.hand_off)) is not None
        )
        + "; on the view it then moves on to the next view, the touch that hands back): its "
        "effort counts the time the robot held alone, as a sonographer's would."
    )
    for a, b in equal_laws:
        intro.text.append(
            f"'{MODES[a].label}' and '{MODES[b].label}' give the controller and the estimator the "
            "same parameters today (the defaults are the seed's law), so their numbers are the "
            "same (each such run is run once and reported under both); both stay so that a "
            "change of the defaults shows against the seed."
        )
    if summary["quick"] or n < FULL_OPERATORS:
        intro.text.append(
            f"A short study ({n} operators"
            + (", shorter tasks" if summary["quick"] else "")
            + "): the targets are the full study's (at least 20 operators), so they are not judged."
        )

    fang = Section("Fang 2017 beside ours")
    rows = []
    for task in TASKS:
        for mode in ASSISTED:
            e = tasks[task][mode]
            rows.append(
                [
                    task,
                    MODES[mode].label,
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
    rows = []
    for mode in ASSISTED:
        t = summary["targets"][mode]

        def met(flag: bool | None) -> str:
            return "not judged (short study)" if flag is None else ("met" if flag else "not met")

        rows.append(
            [
                MODES[mode].label,
                "at least 75 % less for every operator (view, scan)",
                f"{_f(t['hand_force_reduction_pct_smallest'], '.0f')} % (smallest)",
                met(t["hand_force_reduction_met"]),
            ]
        )
        rows.append(
            [
                MODES[mode].label,
                "jitter at least 20 % better (mean, every task)",
                f"{_f(t['jitter_improvement_pct_smallest_mean'], '.0f')} % (smallest mean)",
                met(t["jitter_improvement_met"]),
            ]
        )
    h = summary["targets"]["hold_on_release"]
    rows.append(
        [
            MODES[HOLD].label,
            "contact force std at most 0.5 N through breathing (hands off), no contact loss",
            f"{_f(h['contact_force_std_N_largest'], '.2f')} N (largest), "
            f"{_f(h['contact_losses_largest'], '.0f')} losses (most)",
            met(h["met"]),
        ]
    )
    rows.append(
        [
            MODES[HOLD].label,
            "hand-back tip jump at most 1 mm",
            f"{_f(h['handback_jump_m_largest'], '.2f', 1e3)} mm (largest)",
            met(h["met"]),
        ]
    )
    targets.tables.append(Table("the issue's targets", ["mode", "target", "ours", ""], rows))
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
        for task, e in summary["hold_on_release"].items()
    ]
    targets.tables.append(
        Table(
            "hold-on-release, per operator (smallest to largest)",
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
        for mode in MODES:
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
                    MODES[mode].label,
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
    line = (
        f"{summary['operators']} operators x {len(TASKS)} tasks x {len(MODES)} modes = "
        f"{summary['runs']} runs ({kind}, seed {summary['seed']}), {summary['wall_s']:.0f} s"
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
