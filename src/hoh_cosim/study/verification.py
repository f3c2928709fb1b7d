"""The verification report: the seed's experiments (000, Fig. 16-21) as reproducible runs, with the
seed's numbers beside ours, the linear analysis, and the tuning that beats the seed.

    hoh-cosim report [--out DIR] [--quick] [--workers N] [--scheduler ADDRESS] [--scenarios DIR]

Every figure comes from scenario runs (all of them in one batch on Dask, see `hoh_cosim.study.sweep`)
or from python-control; nothing is typed in but the seed's own numbers, which are quoted as such.
`--quick` runs every section with fewer settings, one seed and shorter runs (for tests and a first
look); the full report uses three seeds for the noise figures and longer runs.

DIR gets `index.html` (the page, PNG figures beside it), `report.md` (the tables in Markdown),
`runs.csv` (every run: its overrides, status and metrics) and `summary.json` (the headline
figures). The directory is replaced whole and only when everything is written.
"""

from __future__ import annotations

import dataclasses
import html
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.errors import ConfigError
from hoh_cosim.study import tune as tuning
from hoh_cosim.study.linear import (
    OMEGA,
    filter_response,
    lag_ms,
    loop_margins,
    loop_model,
)
from hoh_cosim.study.sweep import Outcome, RunPool, Variant, set_option, table_rows

__all__ = ["FULL", "QUICK", "ReportSettings", "build_report"]

SEED = {
    "noise_before_N": [1.15, 1.06, 0.31],
    "noise_after_N": [0.58, 0.48, 0.12],
    "lag_ms": 10.0,
    "mg_N": 4.7631,
    "scale_mass_kg": 0.48,
    "p_com_xy_m": [-0.01250, -0.00033],
    "residual_range": "most poses within the sensor's noise, ±1 N and ±1 N·m (5.B)",
}
"""The seed's own figures (000, sections 4.B, 4.C, 5.B), quoted."""


@dataclass(frozen=True)
class ReportSettings:
    quick: bool
    seeds: tuple[int, ...]  # for the noise and tuning figures
    static_s: float
    circles_s: float
    contact_s: float
    release_s: float
    kalman_multiples: tuple[float, ...]
    butterworth_hz: tuple[float, ...]
    one_euro_hz: tuple[float, ...]
    release_settings: tuple[str, ...]  # labels from the filter settings
    gravity: dict[str, Any]  # sequencer parameters
    tune_candidates: int
    tune_seed: int = 1


QUICK = ReportSettings(
    quick=True,
    seeds=(1,),
    static_s=8.0,
    circles_s=12.0,
    contact_s=16.0,
    release_s=10.0,
    kalman_multiples=(0.1, 1.0, 10.0),
    butterworth_hz=(3.0, 5.0, 10.0),
    one_euro_hz=(1.0, 3.0),
    release_settings=("kalman ×1", "butterworth 5 Hz", "1€ 1 Hz", "raw"),
    gravity={"tilts": 2, "directions": 8, "hold_s": 1.0, "settle_s": 0.5, "move_s": 3.0},
    tune_candidates=6,
)
FULL = ReportSettings(
    quick=False,
    seeds=(1, 2, 3),
    static_s=15.0,
    circles_s=30.0,
    contact_s=30.0,
    release_s=10.0,
    kalman_multiples=(0.01, 0.1, 1.0, 10.0, 100.0),
    butterworth_hz=(2.0, 3.0, 5.0, 10.0, 20.0),
    one_euro_hz=(0.3, 1.0, 3.0, 10.0),
    release_settings=(
        "kalman ×0.1",
        "kalman ×1",
        "kalman ×10",
        "butterworth 3 Hz",
        "butterworth 5 Hz",
        "butterworth 10 Hz",
        "1€ 1 Hz",
        "1€ 3 Hz",
        "raw",
    ),
    gravity={"tilts": 4, "directions": 8, "hold_s": 5.0, "settle_s": 0.5, "move_s": 3.0},
    tune_candidates=60,
)


# -- the runs ------------------------------------------------------------------------------------


@dataclass
class _Batch:
    """Named variants, run together."""

    scenarios: Path
    variants: dict[str, Variant] = field(default_factory=dict)

    def add(
        self,
        tag: str,
        scenario: str,
        overrides: Sequence[str] = (),
        *,
        seed: int | None = None,
        duration_s: float | None = None,
        keep: Sequence[str] = (),
        keep_data: bool = False,
    ) -> None:
        self.variants[tag] = Variant(
            len(self.variants),
            str((self.scenarios / scenario).resolve()),
            tuple(overrides),
            (("tag", tag),),
            seed,
            duration_s,
            "inprocess",
            tuple(keep),
            10,
            keep_data,
        )


def _filter_settings(s: ReportSettings, base_q: np.ndarray) -> dict[str, tuple[str, ...]]:
    """Label -> overrides for every filter tuning the report compares."""
    settings: dict[str, tuple[str, ...]] = {}
    for m in s.kalman_multiples:
        settings[f"kalman ×{m:g}"] = (
            "estimator.filter=kalman",
            set_option("estimator.hand_force_kalman.q", [float(v) for v in base_q * m]),
        )
    for fc in s.butterworth_hz:
        settings[f"butterworth {fc:g} Hz"] = (
            "estimator.filter=butterworth",
            set_option("estimator.butterworth.cutoff_hz", fc),
        )
    for fc in s.one_euro_hz:
        settings[f"1€ {fc:g} Hz"] = (
            "estimator.filter=one_euro",
            set_option("estimator.one_euro_force.min_cutoff_hz", fc),
        )
    settings["raw"] = ("estimator.filter=none",)
    return settings


LAW_SETS: dict[str, tuple[str, ...]] = {
    "seed law (defaults)": (),
    "new laws, seed gains": (
        "estimator.filter=lead_lowpass",
        "controller.translation.law=variable",
        "controller.release.enabled=true",
        "controller.passivity.enabled=true",
    ),
    "new laws, tuned gains": (
        "estimator.filter=lead_lowpass",
        "controller.translation.law=variable",
        "controller.release.enabled=true",
        "controller.passivity.enabled=true",
        "controller.translation.slope=[0.0145,0.0145,0.0145]",
        "controller.translation.deadband=[0.45,0.45,0.25]",
    ),
}
"""The laws the report puts side by side: the seed's law with today's defaults, the issue-22 pieces
(filter without a peak, variable law, release braking, passivity controller) with the seed's gains,
and with the gains tuned for effort at a 2.0 gain margin
(`docs/decisions/0036-transparency-pieces-off-by-default.md`)."""

POPULATION = ((300.0, 0.15), (1000.0, 0.15), (3000.0, 0.25))
"""[N/m], [s] Operators of the population the report runs each law set with (studies/population.yaml
runs the whole grid)."""


def _family(label: str) -> str:
    return label.split(" ")[0]


CIRCLE_FORCE_N = 6.0
"""[N] About the hand force's amplitude on circles, where the 1€ filter is linearised."""
CIRCLE_SIGNALS = ("controller.twist_B", "plant.twist_B", "plant.p_BT_B", "operator.p_ref_B")
CONTACT_SIGNALS = ("plant.F_contact_B", "plant.p_BT_B", "plant.penetration", "operator.F_hand_B")
RELEASE_SIGNALS = ("plant.twist_B", "plant.p_BT_B")


# -- tables --------------------------------------------------------------------------------------


@dataclass
class Table:
    title: str
    header: list[str]
    rows: list[list[str]]

    def markdown(self) -> str:
        def line(cells: Sequence[str]) -> str:
            return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

        lines = [f"**{self.title}**", "", line(self.header), "|" + "---|" * len(self.header)]
        lines += [line(r) for r in self.rows]
        return "\n".join(lines) + "\n"

    def html(self) -> str:
        head = "".join(f"<th>{html.escape(h)}</th>" for h in self.header)
        body = "".join(
            "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
            for row in self.rows
        )
        return (
            f"<table><caption>{html.escape(self.title)}</caption>"
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
        )


def _f(value: Any, fmt: str = ".3g", scale: float = 1.0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, list | tuple):
        return "/".join(_f(v, fmt, scale) for v in value)
    return format(value * scale if scale != 1.0 else value, fmt)


@dataclass
class Section:
    title: str
    text: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[tuple[str, str]] = field(default_factory=list)  # file, caption


@dataclass
class ReportResult:
    out: Path
    sections: list[Section]
    summary: dict[str, Any]
    outcomes: list[Outcome]


# -- the report ----------------------------------------------------------------------------------


def _needed(scenarios: Path) -> None:
    for name in (
        "circles.yaml",
        "static_noise.yaml",
        "release.yaml",
        "contact_scan.yaml",
        "contact_scan_fixture.yaml",
        "gravity_calibration.yaml",
    ):
        if not (scenarios / name).is_file():
            raise ConfigError(
                f"--scenarios {scenarios}: no {name} there (run from a checkout of hoh-cosim, "
                "or pass --scenarios DIR)"
            )


def _metric(outcome: Outcome | None, key: str) -> Any:
    if outcome is None or not outcome.ok:
        return None
    return outcome.metrics.get(key)


def build_report(
    out: str | Path,
    settings: ReportSettings,
    *,
    scenarios: str | Path = "scenarios",
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
) -> ReportResult:
    """Run everything the report needs, draw it, and write it to `out` (replaced whole)."""
    from hoh_cosim.cosim.run import jsonable
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.results import check_out_dir, replace_dir

    out = Path(out)
    scenarios = Path(scenarios)
    check_out_dir(out, marker="report.md", what="report")
    _needed(scenarios)
    started = time.perf_counter()
    s = settings
    circles = load_scenario(scenarios / "circles.yaml")
    base_q = np.asarray(circles.component_of_kind("estimator").params.hand_force_kalman.q)
    filters = _filter_settings(s, base_q)

    batch = _Batch(scenarios)
    for label, overrides in filters.items():
        for seed in s.seeds:
            batch.add(
                f"static|{label}|{seed}",
                "static_noise.yaml",
                overrides,
                seed=seed,
                duration_s=s.static_s,
            )
        batch.add(
            f"circles|{label}",
            "circles.yaml",
            overrides,
            duration_s=s.circles_s,
            keep=CIRCLE_SIGNALS if label == "kalman ×1" else (),
        )
    batch.add(
        "circles|sigmoid",
        "circles.yaml",
        ("controller.translation.law=sigmoid",),
        duration_s=s.circles_s,
        keep=CIRCLE_SIGNALS,
    )
    gravity = [set_option(f"sequencer.{k}", v) for k, v in s.gravity.items()]
    poses = s.gravity["tilts"] * s.gravity["directions"]
    gravity_s = poses * (s.gravity["move_s"] + s.gravity["settle_s"] + s.gravity["hold_s"])
    for cable in (False, True):
        batch.add(
            f"gravity|{cable}",
            "gravity_calibration.yaml",
            [*gravity, set_option("plant.tool.cable.enabled", cable)],
            duration_s=gravity_s,
            keep_data=True,
        )
    contact_modes = {
        "no compensation": ("contact_scan.yaml", ("controller.contact_compensation=false",)),
        "eq. 12": ("contact_scan.yaml", ()),
        "virtual fixture": ("contact_scan_fixture.yaml", ()),
    }
    for mode, (file, overrides) in contact_modes.items():
        for ideal in (False, True):
            batch.add(
                f"contact|{mode}|{ideal}",
                file,
                [*overrides, set_option("fse103.ideal", ideal)],
                duration_s=s.contact_s,
                keep=CONTACT_SIGNALS,
            )
    for label in s.release_settings:
        batch.add(
            f"release|{label}",
            "release.yaml",
            filters[label],
            duration_s=s.release_s,
            keep=RELEASE_SIGNALS,
        )
    for law, overrides in LAW_SETS.items():
        for scenario, duration in (
            ("circles.yaml", s.circles_s),
            ("release.yaml", s.release_s),
            ("contact_scan.yaml", s.contact_s),
        ):
            batch.add(f"laws|{law}|{scenario}", scenario, overrides, duration_s=duration)
        for stiffness, delay in _population(s):
            batch.add(
                f"laws|{law}|population|{stiffness:g}|{delay:g}",
                "circles.yaml",
                (
                    *overrides,
                    set_option("operator.stiffness", stiffness),
                    set_option("operator.reaction_delay_s", delay),
                ),
                duration_s=s.circles_s,
            )
    with RunPool(workers=workers, scheduler=scheduler, progress=progress, label="report") as pool:
        # the runs that do not depend on the linear analysis step while it is computed
        pool.submit(list(batch.variants.values()))
        linear = _linear_analysis(circles, filters, s)
        candidates = tuning.make_candidates(
            scenarios / "circles.yaml", s.tune_candidates, s.tune_seed
        )
        first = len(batch.variants)
        critical = linear["default_margins"].critical_slope
        for factor in (0.8, 1.25):
            a = critical * factor
            batch.add(
                f"stability|{factor}",
                "circles.yaml",
                (set_option("controller.translation.slope", [a, a, a]),),
                duration_s=s.circles_s,
            )
        tune_runs = tuning.tune_variants(
            candidates,
            scenarios / "static_noise.yaml",
            scenarios / "circles.yaml",
            s.seeds,
            static_s=s.static_s,
            circles_s=s.circles_s,
        )
        for i, (index, what, variant) in enumerate(tune_runs):
            batch.variants[f"tune|{index}|{what}|{i}"] = dataclasses.replace(
                variant, index=len(batch.variants), values=(("tag", f"tune {index} {what}"),)
            )
        tags = list(batch.variants)
        pool.submit([batch.variants[t] for t in tags[first:]])
        outcomes = pool.results()
    got = dict(zip(tags, outcomes, strict=True))
    evaluations = tuning.evaluate(
        candidates,
        [
            (index, what, got[f"tune|{index}|{what}|{i}"])
            for i, (index, what, _) in enumerate(tune_runs)
        ],
        tuning.Constraints(),
    )

    figures: dict[str, bytes] = {}
    sections = [
        _noise_vs_lag(got, filters, s, linear, evaluations, figures),
        _admittance(got, figures),
        _gravity(got, figures, circles),
        _contact(got, contact_modes, figures),
        _release(got, s, figures),
        _linear_section(got, linear, figures),
        _tuning_section(evaluations, figures),
    ]
    sections.append(_seed_versus_us(got, s, evaluations))
    sections.append(_laws_section(got, circles, s))
    failed = [(t, o.error) for t, o in got.items() if not o.ok]
    summary = _summary(got, s, linear, evaluations, failed, time.perf_counter() - started)

    columns, rows = table_rows(outcomes)

    def fill(staging: Path) -> None:
        from hoh_cosim.study.sweep import write_table

        for name, data in figures.items():
            (staging / name).write_bytes(data)
        write_table(staging, columns, rows)
        (staging / "summary.json").write_text(
            json.dumps(jsonable(summary), indent=2, allow_nan=False) + "\n", "utf-8"
        )
        (staging / "index.html").write_text(
            page_html(*_header(summary), sections, _CSS), encoding="utf-8"
        )
        (staging / "report.md").write_text(
            page_markdown(*_header(summary), sections), encoding="utf-8"
        )

    replace_dir(out, fill, what="report")
    return ReportResult(out, sections, summary, outcomes)


# -- sections ------------------------------------------------------------------------------------


def _linear_analysis(circles, filters: dict[str, tuple[str, ...]], s: ReportSettings) -> dict:
    """Each filter setting's lag at the circle frequency and the loop margins, from python-control."""
    from hoh_cosim.cosim.scenario import load_scenario

    op = circles.component_of_kind("operator").params
    w0 = 2.0 * math.pi / op.period_s
    # the 1€ filter is linearised at the mean rate of change of the hand force on a circle: a
    # sinusoid of amplitude a at f changes at 4 a f on average; the circles' hand force is about
    # 6 N in magnitude (hand_force_rms_N)
    speed = 4.0 * CIRCLE_FORCE_N / op.period_s
    result: dict[str, Any] = {"w0": w0, "speed": speed, "filters": {}}
    for label, overrides in filters.items():
        scenario = load_scenario(circles.path, overrides)
        est = scenario.component_of_kind("estimator").params
        gain = filter_response(est, OMEGA, signal_speed=speed)
        g0 = filter_response(est, np.array([w0]), signal_speed=speed)[0]
        result["filters"][label] = {
            "gain": gain,
            "lag_ms": lag_ms(g0, w0),
            "gain_at_w0": float(abs(g0)),
            "peak_gain": float(np.max(np.abs(gain))),
            "margins": loop_margins(loop_model(scenario), gain, OMEGA),
        }
    result["default_margins"] = result["filters"]["kalman ×1"]["margins"]
    result["model"] = loop_model(circles)
    slopes = np.linspace(0.002, 0.04, 39)
    # L is proportional to the slope, so the gain margin at slope a is the critical slope over a
    result["curves"] = {
        label: f["margins"].critical_slope / slopes
        for label, f in result["filters"].items()
        if label in ("kalman ×0.1", "kalman ×1", "kalman ×10", "butterworth 5 Hz", "1€ 1 Hz", "raw")
    }
    result["slopes"] = slopes
    return result


def _noise_vs_lag(got, filters, s, linear, evaluations, figures) -> Section:
    from hoh_cosim.cosim.plots import png, pyplot

    sec = Section("1. Noise versus lag")
    sec.text.append(
        "Every filter the seed compared, across its tuning range: the noise attenuation on "
        "static_noise (max |noise| raw / filtered, the smallest of the three base axes, mean over "
        f"{len(s.seeds)} seed(s)) against the lag it adds on circles (filtered behind the held raw "
        "reading at the circle frequency, the seed's Fig. 20 measure; negative is a lead). The "
        "linear-model column is python-control's prediction of that lag (section 6)."
    )
    rows, points = [], {}
    for label in filters:
        static = [got[f"static|{label}|{seed}"] for seed in s.seeds]
        att, axes = tuning.mean_attenuation(static)
        circ = got[f"circles|{label}"]
        lag = _metric(circ, "filter_lag_ms")
        points[label] = (lag, att)
        rows.append(
            [
                label,
                _f(axes, ".2f"),
                _f(att, ".2f"),
                _f(lag, ".1f"),
                _f(linear["filters"][label]["lag_ms"], ".1f"),
                _f(_metric(circ, "hand_force_rms_N"), ".2f"),
                _f(_metric(circ, "path_rms_error_m"), ".1f", 1e3),
                "yes" if tuning.beats_seed(att, lag) else "no",
            ]
        )
    sec.tables.append(
        Table(
            "filters on static_noise and circles",
            [
                "filter",
                "attenuation x/y/z",
                "min",
                "lag [ms]",
                "lag, linear model [ms]",
                "hand force RMS [N]",
                "path error RMS [mm]",
                "beats the seed",
            ],
            rows,
        )
    )
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    ax.axvspan(-50, 10, ymin=0, ymax=1, color="0.95")
    for family, marker in (("kalman", "o"), ("butterworth", "s"), ("1€", "^"), ("raw", "x")):
        pts = [(lbl, p) for lbl, p in points.items() if _family(lbl) == family]
        xs = [p[0] for _, p in pts if None not in p]
        ys = [p[1] for _, p in pts if None not in p]
        if xs:
            ax.plot(xs, ys, marker=marker, label=family)
            for lbl, p in pts:
                if None not in p:
                    ax.annotate(
                        lbl.split(" ", 1)[-1],
                        p,
                        fontsize=7,
                        xytext=(3, 3),
                        textcoords="offset points",
                    )
    ax.plot(
        [tuning.SEED_LAG_MS], [tuning.SEED_ATTENUATION], "k*", ms=14, label="seed (Fig. 18, 20)"
    )
    top = tuning.best(evaluations)
    if top is not None and top.lag_ms is not None and top.attenuation is not None:
        ax.plot([top.lag_ms], [top.attenuation], "rP", ms=12, label="tuned")
    ax.plot([-50, 10, 10], [3, 3, 0], "k--", lw=0.8)
    ax.plot([-50, 5, 5], [2, 2, 0], "k:", lw=0.8)
    ax.set_xlabel("lag added by the filter at the circle frequency [ms]")
    ax.set_ylabel("noise attenuation, smallest axis [x]")
    ax.set_xscale("symlog", linthresh=10)
    ax.set_title("noise attenuation against lag (dashed: 3x at 10 ms; dotted: 2x at 5 ms)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    figures["pareto.png"] = png(fig)
    sec.figures.append(("pareto.png", "attenuation against lag for every filter and tuning"))
    return sec


def _admittance(got, figures) -> Section:
    from hoh_cosim.cosim.plots import png, pyplot

    sec = Section("2. Linear versus sigmoid admittance (seed Fig. 21)")
    sec.text.append(
        "circles with eq. 10 (deadband and slope) and with the older work's sigmoid law, the same "
        "Kalman filter: the operator's effort, the path error, and the commanded velocity."
    )
    rows = []
    for label, tag in (("eq. 10 (linear)", "circles|kalman ×1"), ("sigmoid", "circles|sigmoid")):
        o = got[tag]
        rows.append(
            [
                label,
                _f(_metric(o, "hand_force_rms_N"), ".2f"),
                _f(_metric(o, "path_rms_error_m"), ".1f", 1e3),
                _f(_metric(o, "velocity_hf_rms_m_s"), ".1f", 1e3),
            ]
        )
    sec.tables.append(
        Table(
            "admittance laws on circles",
            ["law", "hand force RMS [N]", "path error RMS [mm]", "velocity > 1 Hz RMS [mm/s]"],
            rows,
        )
    )
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    for label, tag in (("eq. 10", "circles|kalman ×1"), ("sigmoid", "circles|sigmoid")):
        o = got[tag]
        if o.ok and "controller.twist_B" in o.signals:
            ax.plot(o.time, 1e3 * o.signals["controller.twist_B"][:, 0], lw=1, label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("commanded v_x [mm/s]")
    ax.legend(fontsize=8)
    ax.set_title("commanded velocity along x, linear versus sigmoid gains")
    fig.tight_layout()
    figures["admittance.png"] = png(fig)
    sec.figures.append(("admittance.png", "commanded velocity, eq. 10 against the sigmoid law"))
    return sec


def _tilt_direction(R_BS: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[deg] Each pose's tilt of the sensor's z axis from the vertical, and the direction of the
    tilt about the vertical."""
    z = R_BS[:, :, 2]
    tilt = np.degrees(np.arccos(np.clip(np.abs(z[:, 2]), 0.0, 1.0)))
    direction = np.degrees(np.arctan2(z[:, 1], z[:, 0])) % 360.0
    return tilt, direction


def _gravity(got, figures, circles) -> Section:
    from hoh_cosim.control.gravity import GravityModel
    from hoh_cosim.cosim.plots import gravity_residual_figure, png, pyplot

    sec = Section("3. Gravity compensation (seed Fig. 16, 17)")
    sec.text.append(
        "The batch calibration (eq. 4-8) on the simulated tool without and with cable drag: "
        "per-pose residuals with the bias removed and with the weight model removed too, and the "
        "residual after compensation by the orientation of the pose."
    )
    rows = []
    g_B = circles.component_of_kind("plant").params.g_B
    radar = {}
    for cable in (False, True):
        o = got[f"gravity|{cable}"]
        name = "with cable" if cable else "no cable"
        cal = o.data.get("calibration") if o.ok else None
        if cal is None:
            rows.append([name] + ["n/a"] * 6)
            continue
        R_BS, wrench = o.data["poses"]
        model = GravityModel(cal.tool, g_B)
        after = wrench - cal.bias - np.array([model.weight_S(R) for R in R_BS])
        radar[name] = (R_BS, after)
        rows.append(
            [
                name,
                _f(cal.mass_kg, ".4f"),
                _f(cal.mass_kg * float(np.linalg.norm(g_B)), ".4f"),
                _f(cal.com_m[:2].tolist(), ".5f"),
                _f(o.metrics.get("residual_rms_before_N"), ".2f"),
                _f(o.metrics.get("residual_rms_after_N"), ".3f"),
                f"{np.max(np.abs(after[:, :3])):.3f} N, {np.max(np.abs(after[:, 3:])):.4f} N·m",
            ]
        )
        file = f"gravity_residuals_{'cable' if cable else 'nocable'}.png"
        figures[file] = png(gravity_residual_figure(cal, R_BS, wrench, g_B, f", {name}"))
        sec.figures.append((file, f"per-pose residuals, {name} (Fig. 16)"))
    sec.tables.append(
        Table(
            "identification",
            [
                "tool",
                "m [kg]",
                "mg [N]",
                "p_COM x/y [m]",
                "force residual RMS before x/y/z [N]",
                "after [N]",
                "max abs residual after",
            ],
            rows,
        )
    )
    if radar:
        plt = pyplot()
        fig, axes = plt.subplots(
            len(radar), 3, subplot_kw={"projection": "polar"}, figsize=(11, 3.8 * len(radar))
        )
        axes = np.atleast_2d(axes)
        for r, (name, (R_BS, after)) in enumerate(radar.items()):
            tilt, direction = _tilt_direction(R_BS)
            for k, axis in enumerate(("F_x", "F_y", "F_z")):
                ax = axes[r, k]
                for t in np.unique(np.round(tilt)):
                    sel = np.round(tilt) == t
                    order = np.argsort(direction[sel])
                    theta = np.radians(direction[sel][order])
                    value = np.abs(after[sel, k][order])
                    ax.plot(
                        np.append(theta, theta[:1]),
                        np.append(value, value[:1]),
                        lw=1,
                        label=f"{t:.0f}°",
                    )
                ax.set_title(f"{axis} abs residual [N], {name}", fontsize=9)
            axes[r, 0].legend(fontsize=7, loc="lower left", title="tilt", title_fontsize=7)
        fig.tight_layout()
        figures["gravity_radar.png"] = png(fig)
        sec.figures.append(
            ("gravity_radar.png", "residual after compensation by tilt direction (Fig. 17)")
        )
    return sec


def _press_force(o: Outcome) -> float | None:
    """Mean hand force down along z over the second half of a contact run."""
    if not o.ok:
        return None
    late = o.time >= 0.5 * o.time[-1]
    return float(-np.mean(o.signals["operator.F_hand_B"][late, 2]))


def _contact(got, modes, figures) -> Section:
    from hoh_cosim.cosim.plots import png, pyplot

    sec = Section("4. Contact: bounce, eq. 12, the virtual fixture, the FSE103 housing")
    sec.text.append(
        "contact_scan (press to 8 N, scan 10 cm) without contact compensation, with eq. 12, and "
        "with the virtual fixture of 3.F.3, each with the FSE103 in its housing (backlash and "
        "axis redirection) and with an ideal probe sensor. The simulated hand presses with a force "
        "loop, so without compensation it does not bounce off: it pushes the whole contact force "
        "itself, which the hand-force column shows (mean over the second half of the run, along "
        "the press)."
    )
    rows = []
    for mode in modes:
        for ideal in (False, True):
            o = got[f"contact|{mode}|{ideal}"]
            rows.append(
                [
                    mode,
                    "ideal" if ideal else "housing",
                    _f(_metric(o, "contact_losses"), "d"),
                    _f(_metric(o, "max_bounce_m"), ".2f", 1e3),
                    _f(_metric(o, "contact_force_mean_N"), ".2f"),
                    _f(_metric(o, "contact_force_std_N"), ".2f"),
                    _f(_press_force(o), ".2f"),
                ]
            )
    sec.tables.append(
        Table(
            "contact_scan",
            [
                "mode",
                "FSE103",
                "contact losses",
                "max bounce [mm]",
                "contact force mean [N]",
                "contact force std [N]",
                "hand force along the press [N]",
            ],
            rows,
        )
    )
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    for mode in modes:
        for ax, ideal in zip(axes, (False, True), strict=True):
            o = got[f"contact|{mode}|{ideal}"]
            if o.ok:
                ax.plot(o.time, -o.signals["plant.F_contact_B"][:, 2], lw=1, label=mode)
                ax.set_title(f"FSE103 {'ideal' if ideal else 'in its housing'}", fontsize=9)
                ax.set_ylabel("contact force along z [N]")
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    figures["contact.png"] = png(fig)
    sec.figures.append(("contact.png", "contact force traces"))
    return sec


def _release(got, s, figures) -> Section:
    from hoh_cosim.cosim.plots import png, pyplot

    sec = Section("5. Release inertia per filter")
    sec.text.append(
        "release: a 5 N push, then the hand lets go; how far the tip keeps going and how long until "
        "it stands still (under 1 mm/s), for each filter and tuning: the 'inertia' the seed's users "
        "felt (5.C)."
    )
    rows = []
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    for label in s.release_settings:
        o = got[f"release|{label}"]
        rows.append(
            [
                label,
                _f(_metric(o, "release_drift_m"), ".2f", 1e3),
                _f(_metric(o, "release_settle_s"), ".3f"),
            ]
        )
        if o.ok:
            speed = np.linalg.norm(o.signals["plant.twist_B"][:, :3], axis=1)
            ax.plot(o.time, 1e3 * speed, lw=1, label=label)
    ax.set_xlim(5.5, min(8.0, s.release_s))
    ax.set_xlabel("time [s] (release at 6 s)")
    ax.set_ylabel("tip speed [mm/s]")
    ax.legend(fontsize=7)
    fig.tight_layout()
    figures["release.png"] = png(fig)
    sec.figures.append(("release.png", "tip speed around the release"))
    sec.tables.append(Table("release", ["filter", "drift [mm]", "settle [s]"], rows))
    return sec


def _population(s: ReportSettings) -> tuple[tuple[float, float], ...]:
    """The operators the report runs: all of POPULATION, the stiff and slow one alone if quick."""
    return POPULATION[-1:] if s.quick else POPULATION


def _law_margin(circles, overrides: Sequence[str], push_N: float | None) -> float:
    """The default operator's loop gain margin for a law set: its filter, its slope, and for the
    variable law its schedule linearised about the circles' push (`variable_law_lead`)."""
    from hoh_cosim.control.controller import ControllerParams
    from hoh_cosim.cosim.scenario import load_scenario
    from hoh_cosim.study.linear import variable_law_lead

    scenario = load_scenario(circles.path, tuple(overrides))
    est = scenario.component_of_kind("estimator").params
    ctl: ControllerParams = scenario.component_of_kind("controller").params
    gain = filter_response(est, OMEGA)
    if ctl.translation.law == "variable" and push_N is not None:
        eta = float(ctl.translation.deadband[0])
        excess = max(0.0, push_N / eta - 1.0) if eta > 0 else 0.0
        gain = gain * variable_law_lead(ctl.variable, excess, OMEGA)
    return loop_margins(loop_model(scenario), gain, OMEGA).gain_margin


def _laws_section(got, circles, s: ReportSettings) -> Section:
    sec = Section("8. The laws side by side")
    sec.text.append(
        "The seed's law with today's defaults against the new pieces (the filter without a gain "
        "peak, the variable law, release braking, the passivity controller), with the seed's gains "
        "and with gains tuned for effort: circles (effort and path error), release (drift and "
        "settling), the contact scan (spread of the contact force), the default operator's gain "
        "margin (python-control, the variable law linearised about the circles' push), and the "
        "tip's velocity above 1 Hz over the last circle for a relaxed, a stiff and a stiff and "
        "slow operator (a sustained oscillation when tens of mm/s). `hoh-cosim sweep studies/population.yaml` runs "
        "the whole population."
    )
    rows = []
    for law, overrides in LAW_SETS.items():
        c = got[f"laws|{law}|circles.yaml"]
        r = got[f"laws|{law}|release.yaml"]
        k = got[f"laws|{law}|contact_scan.yaml"]
        pop = [
            _f(
                _metric(got[f"laws|{law}|population|{a:g}|{b:g}"], "velocity_hf_late_rms_m_s"),
                ".3g",
                1e3,
            )
            for a, b in _population(s)
        ]
        rows.append(
            [
                law,
                _f(_metric(c, "hand_force_rms_N"), ".3g"),
                _f(_metric(c, "path_rms_error_m"), ".3g", 1e3),
                _f(_metric(r, "release_drift_m"), ".3g", 1e3),
                _f(_metric(r, "release_settle_s"), ".3g", 1e3),
                _f(_metric(k, "contact_force_std_N"), ".3g"),
                _f(_law_margin(circles, overrides, _metric(c, "hand_force_rms_N")), ".3g"),
                " / ".join(pop),
            ]
        )
    operators = ", ".join(f"{a:g} N/m {1e3 * b:g} ms" for a, b in _population(s))
    sec.tables.append(
        Table(
            "laws",
            [
                "law",
                "hand force RMS [N]",
                "path error RMS [mm]",
                "release drift [mm]",
                "settle [ms]",
                "contact force std [N]",
                "gain margin",
                f"velocity above 1 Hz, last circle [mm/s] ({operators})",
            ],
            rows,
        )
    )
    return sec


def _linear_section(got, linear, figures) -> Section:
    from hoh_cosim.cosim.plots import png, pyplot

    model = linear["model"]
    dm = linear["default_margins"]
    sec = Section("6. Linear analysis (python-control)")
    sec.text.append(
        "Each filter as a discrete linear system against the held raw reading (the Kalman filter in "
        "its steady state over one packet period), and the loop hand -> sensor -> filter -> "
        f"eq. 10 -> robot linearised along x: hand K = {model.hand_stiffness:g} N/m, "
        f"D = {model.hand_damping:g} N·s/m, delays hand {1e3 * model.hand_delay_s:g} ms, sensor "
        f"{1e3 * model.sensor_delay_s:g} ms, robot {1e3 * model.robot_delay_s:g} ms. The 1€ "
        f"filter is linearised at the hand force's {linear['speed']:.1f} N/s: on real data its "
        "speed estimate also sees the sensor noise, which raises its cutoff, so its model lag is "
        "an upper bound (compare section 1's measured column)."
    )
    sec.text.append(
        f"At the defaults (Kalman, slope {model.slope:g} m/(s·N)) the gain margin is "
        f"{dm.gain_margin:.2f} ({dm.gain_margin_db:.1f} dB) and the phase margin "
        f"{dm.phase_margin_deg:.0f}°: the loop loses stability at a slope of "
        f"{dm.critical_slope:.4f}, {dm.gain_margin:.2f}x the default. The constant-acceleration "
        "Kalman filter's gain peaks above 1 (its lead), which is what sets the margin."
    )
    rows = []
    for label, f in linear["filters"].items():
        m = f["margins"]
        rows.append(
            [
                label,
                _f(f["gain_at_w0"], ".3f"),
                _f(f["lag_ms"], ".1f"),
                _f(f["peak_gain"], ".2f"),
                _f(m.gain_margin, ".2f"),
                _f(m.phase_margin_deg, ".0f"),
                _f(m.critical_slope, ".4f"),
            ]
        )
    sec.tables.append(
        Table(
            "filters and loop margins at the default slope",
            [
                "filter",
                "gain at the circle frequency",
                "lag [ms]",
                "peak gain",
                "gain margin",
                "phase margin [°]",
                "critical slope [m/(s·N)]",
            ],
            rows,
        )
    )
    rows = []
    for factor in (0.8, 1.25):
        o = got[f"stability|{factor}"]
        rows.append(
            [
                f"{factor:g} x critical ({factor * dm.critical_slope:.4f})",
                _f(_metric(o, "velocity_hf_rms_m_s"), ".1f", 1e3),
                _f(_metric(o, "hand_force_rms_N"), ".2f"),
                str(_metric(o, "controller_flags")),
            ]
        )
    o = got["circles|kalman ×1"]
    rows.insert(
        0,
        [
            f"default ({model.slope:g})",
            _f(_metric(o, "velocity_hf_rms_m_s"), ".1f", 1e3),
            _f(_metric(o, "hand_force_rms_N"), ".2f"),
            str(_metric(o, "controller_flags")),
        ],
    )
    sec.tables.append(
        Table(
            "the prediction checked in simulation (circles)",
            ["slope", "velocity > 1 Hz RMS [mm/s]", "hand force RMS [N]", "controller limits"],
            rows,
        )
    )
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    hz = OMEGA / (2 * math.pi)
    for label, f in linear["filters"].items():
        if label in ("kalman ×0.1", "kalman ×1", "kalman ×10", "butterworth 5 Hz", "1€ 1 Hz"):
            axes[0].semilogx(hz, 20 * np.log10(np.abs(f["gain"])), lw=1, label=label)
            axes[1].semilogx(hz, np.degrees(np.angle(f["gain"])), lw=1)
    axes[0].axvline(linear["w0"] / (2 * math.pi), color="k", lw=0.6, ls="--")
    axes[0].set_ylabel("gain [dB]")
    axes[1].set_ylabel("phase [°]")
    axes[1].set_xlabel("frequency [Hz]")
    axes[0].legend(fontsize=7)
    axes[0].set_title("filters against the held raw reading (dashed: the circle frequency)")
    fig.tight_layout()
    figures["bode.png"] = png(fig)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, gms in linear["curves"].items():
        ax.plot(linear["slopes"], gms, lw=1, label=label)
    ax.axhline(1.0, color="r", lw=0.8)
    ax.axhline(2.0, color="k", lw=0.8, ls=":")
    ax.axvline(model.slope, color="k", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_xlabel("slope α [m/(s·N)] (dashed: default)")
    ax.set_ylabel("gain margin (1: unstable; dotted: 6 dB)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    figures["margins.png"] = png(fig)
    sec.figures += [
        ("bode.png", "frequency responses"),
        ("margins.png", "gain margin against slope per filter"),
    ]
    return sec


def _tuning_section(evaluations, figures) -> Section:
    from hoh_cosim.cosim.plots import png, pyplot

    c = tuning.Constraints()
    sec = Section("Tuning that beats the seed")
    ran = [ev for ev in evaluations if ev.ran]
    sec.text.append(
        f"{len(evaluations) - 1} Latin-hypercube candidates (Kalman q multiple for x/y and z, "
        "deadband for x/y and z, slope) and the defaults. A candidate runs only if its linearised "
        f"loop has a gain margin >= {c.min_gain_margin:g} and a phase margin >= "
        f"{c.min_phase_margin_deg:g}° ({len(ran) - 1} did); it is feasible when it beats the seed "
        "on noise and lag at once (>= 3x at <= 10 ms, or >= 2x at <= 5 ms) and the untouched tip "
        f"moves less than {1e3 * c.max_rest_motion_m:g} mm. Score: effort / effort of the defaults "
        "+ path error / path error of the defaults (the defaults score 2)."
    )
    top = tuning.best(evaluations)
    ranked = sorted(
        [ev for ev in ran], key=lambda ev: (not ev.feasible, ev.score if ev.score else math.inf)
    )
    rows = []
    for ev in ranked[:12]:
        v = ev.candidate.values
        rows.append(
            [
                ev.candidate.label,
                _f(v.get("q_multiple_xy"), ".3g") if v else "1",
                _f(v.get("q_multiple_z"), ".3g") if v else "1",
                _f(v.get("deadband_xy_N"), ".2f") if v else "default",
                _f(v.get("slope"), ".4f") if v else "default",
                _f(ev.candidate.margins.gain_margin, ".2f"),
                _f(ev.attenuation, ".2f"),
                _f(ev.lag_ms, ".1f"),
                _f(ev.effort_N, ".2f"),
                _f(ev.path_error_m, ".1f", 1e3),
                _f(ev.score, ".3f"),
                ev.reason,
            ]
        )
    sec.tables.append(
        Table(
            "candidates, best first",
            [
                "setting",
                "q × (x/y)",
                "q × (z)",
                "η x/y [N]",
                "α",
                "gain margin",
                "attenuation",
                "lag [ms]",
                "hand force RMS [N]",
                "path error [mm]",
                "score",
                "verdict",
            ],
            rows,
        )
    )
    if top is None:
        sec.text.append("No candidate was feasible: widen the search (`hoh-cosim tune -n`).")
    else:
        sec.text.append(
            f"Best: {top.candidate.label}, "
            + ", ".join(f"{k} {v:.4g}" for k, v in top.candidate.values.items())
            + f": attenuation {top.attenuation:.2f}x at {top.lag_ms:.1f} ms lag (the seed: about "
            f"2x at about 10 ms), score {top.score:.3f}. As --set options: "
            + " ".join(f"--set {o}" for o in top.candidate.overrides)
        )
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    for ev in ran:
        if ev.effort_N is None or ev.path_error_m is None:
            continue
        color = "tab:green" if ev.feasible else "0.6"
        ax.plot(ev.effort_N, 1e3 * ev.path_error_m, "o", color=color, ms=5)
    ref = evaluations[0]
    if ref.effort_N is not None:
        ax.plot(ref.effort_N, 1e3 * ref.path_error_m, "ks", ms=9, label="defaults")
    if top is not None:
        ax.plot(top.effort_N, 1e3 * top.path_error_m, "rP", ms=12, label="best feasible")
    ax.set_xlabel("operator effort: hand force RMS [N]")
    ax.set_ylabel("path error RMS [mm]")
    ax.set_title("tuning candidates (green: feasible)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    figures["tuning.png"] = png(fig)
    sec.figures.append(("tuning.png", "effort against path error for every candidate that ran"))
    return sec


def _seed_versus_us(got, s: ReportSettings, evaluations) -> Section:
    sec = Section("7. Seed versus us")
    sec.text.append(
        "Every figure the seed reports, next to ours measured the same way (the defaults unless "
        "the row says otherwise). The seed's are read from its text (000, 4.B, 4.C, 5.B)."
    )
    static = [got[f"static|kalman ×1|{seed}"] for seed in s.seeds]
    raw = tuning.mean_metric(static, "noise_max_abs_raw_N")
    filtered = tuning.mean_metric(static, "noise_max_abs_filtered_N")
    lag = _metric(got["circles|kalman ×1"], "filter_lag_ms")
    est_lag = _metric(got["circles|kalman ×1"], "estimate_lag_ms")
    rows = [
        ["max abs noise before, x/y/z [N]", _f(SEED["noise_before_N"], ".2f"), _f(raw, ".2f")],
        ["max abs noise after, x/y/z [N]", _f(SEED["noise_after_N"], ".2f"), _f(filtered, ".2f")],
        [
            "attenuation x/y/z",
            _f(list(np.divide(SEED["noise_before_N"], SEED["noise_after_N"])), ".2f"),
            _f(list(np.divide(raw, filtered)) if raw and filtered else None, ".2f"),
        ],
        ["lag added by the filter [ms]", "about 10", _f(lag, ".1f")],
        ["estimate behind the true hand force [ms]", "not measured", _f(est_lag, ".1f")],
    ]
    for cable in (True, False):
        o = got[f"gravity|{cable}"]
        cal = o.data.get("calibration") if o.ok else None
        name = "with cable" if cable else "no cable"
        if cal is None:
            continue
        rows += [
            [
                f"-mg [N], {name}",
                f"-{SEED['mg_N']:.4f} (scale: 0.48 kg)",
                f"-{cal.mass_kg * 9.81:.4f} (simulated: 0.48 kg)",
            ],
            [
                f"p_COM x/y [m], {name}",
                _f(SEED["p_com_xy_m"], ".5f"),
                _f(cal.com_m[:2].tolist(), ".5f"),
            ],
            [
                f"residual after, {name}",
                SEED["residual_range"],
                f"RMS {_f(o.metrics.get('residual_rms_after_N'), '.3f')} N",
            ],
        ]
    top = tuning.best(evaluations)
    if top is not None:
        rows.append(
            [
                "tuned: attenuation at lag",
                "about 2x at about 10 ms",
                f"{top.attenuation:.2f}x at {top.lag_ms:.1f} ms",
            ]
        )
    sec.tables.append(Table("seed versus us", ["figure", "seed", "hoh-cosim"], rows))
    return sec


# -- output --------------------------------------------------------------------------------------


def _summary(got, s, linear, evaluations, failed, wall_s) -> dict[str, Any]:
    top = tuning.best(evaluations)
    dm = linear["default_margins"]
    static = [got[f"static|kalman ×1|{seed}"] for seed in s.seeds]
    att, axes = tuning.mean_attenuation(static)
    return {
        "quick": s.quick,
        "runs": len(got),
        "failed_runs": [f"{tag}: {error}" for tag, error in failed],
        "wall_s": wall_s,
        "default": {
            "attenuation_axes": axes,
            "attenuation_min": att,
            "filter_lag_ms": _metric(got["circles|kalman ×1"], "filter_lag_ms"),
            "hand_force_rms_N": _metric(got["circles|kalman ×1"], "hand_force_rms_N"),
            "path_rms_error_m": _metric(got["circles|kalman ×1"], "path_rms_error_m"),
            "gain_margin": dm.gain_margin,
            "phase_margin_deg": dm.phase_margin_deg,
            "critical_slope": dm.critical_slope,
            "beats_seed": tuning.beats_seed(
                att, _metric(got["circles|kalman ×1"], "filter_lag_ms")
            ),
        },
        "linear_lag_ms": {k: v["lag_ms"] for k, v in linear["filters"].items()},
        "tuned": None
        if top is None
        else {
            "values": dict(top.candidate.values),
            "set": list(top.candidate.overrides),
            "attenuation_min": top.attenuation,
            "filter_lag_ms": top.lag_ms,
            "hand_force_rms_N": top.effort_N,
            "path_rms_error_m": top.path_error_m,
            "gain_margin": top.candidate.margins.gain_margin,
            "score": top.score,
            "beats_seed": tuning.beats_seed(top.attenuation, top.lag_ms),
        },
    }


_CSS = (
    "body{font-family:sans-serif;max-width:1100px;margin:2em auto;line-height:1.4}"
    "table{border-collapse:collapse;margin:1em 0;font-size:90%}"
    "td,th{border:1px solid #bbb;padding:3px 6px}caption{font-weight:bold;text-align:left}"
    "img{max-width:100%}"
)


def _header(summary: dict[str, Any]) -> tuple[str, str]:
    kind = "quick" if summary["quick"] else "full"
    lines = f"{summary['runs']} runs ({kind}), {summary['wall_s']:.0f} s"
    if summary["failed_runs"]:
        lines += f"; {len(summary['failed_runs'])} failed: " + "; ".join(summary["failed_runs"])
    return "hoh-cosim verification report", lines


def page_html(title: str, line: str, sections: Sequence[Section], css: str) -> str:
    """A report's `index.html`: its title, a line under it, then each section's text, tables and
    figures (the verification report's and the clinical study's)."""
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{css}</style></head><body><h1>{html.escape(title)}</h1>"
        f"<p>{html.escape(line)}</p>"
    ]
    for sec in sections:
        parts.append(f"<h2>{html.escape(sec.title)}</h2>")
        parts += [f"<p>{html.escape(t)}</p>" for t in sec.text]
        parts += [t.html() for t in sec.tables]
        parts += [
            f"<figure><img src='{f}' alt='{html.escape(c)}'><figcaption>{html.escape(c)}"
            "</figcaption></figure>"
            for f, c in sec.figures
        ]
    parts.append("</body></html>\n")
    return "\n".join(parts)


def page_markdown(title: str, line: str, sections: Sequence[Section]) -> str:
    """The same report as `report.md`."""
    parts = [f"# {title}\n", f"{line}\n"]
    for sec in sections:
        parts.append(f"## {sec.title}\n")
        parts += [f"{t}\n" for t in sec.text]
        parts += [t.markdown() for t in sec.tables]
        parts += [f"![{c}]({f})\n" for f, c in sec.figures]
    return "\n".join(parts)
