"""`hoh-cosim probe-correction`: the seed's probe-force network, its day-two failure, the online map.

    record probe_data.yaml (the hand off the handle presses the probe tip, the robot holds still,
    the compensated wrist force is the reference) three times:
        training  day one (housing session 1), 120 s
        day one   day one again, another 60 s with other pushes (the seed's Fig. 14)
        day two   the next day (session 2), 60 s (the seed's Fig. 15)
    train the seed's three networks on the training recording (scikit-learn's MLPRegressor, one
        hidden layer of 20 logistic neurons, one network per axis, all three readings in; 70 % to
        train, 15 % validation, 15 % test, MATLAB's default split); their validation correlation is
        the seed's 0.945 / 0.981 / 0.998
    table: correlation and RMS error per axis against the reference, of the raw reading, the
        network and the online map (`hoh_cosim.control.probe_correction`), on day one and day two
    contact_scan_online.yaml with each correction in the loop (contact compensation, eq. 12), on
        day one and day two: the contact_scan metrics and what the consistency check said

The online map's figures are its predictions before it learns from each sample, from the identity
each day: it carries nothing over from day one, so it cannot be hurt by what changed overnight.

Writes report.md, summary.json, table.csv, network.json (the network as `--set` takes it) and the
figures fig13_regression.png, fig14_day_one.png, fig15_day_two.png, contact_scan.png.
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.control.probe_correction import HIDDEN, network_forward, pack_network
from hoh_cosim.cosim.plots import png, probe_forces_figure, pyplot
from hoh_cosim.cosim.report import ProbeSamples, axis_correlation, axis_rms
from hoh_cosim.cosim.run import jsonable
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.results import check_out_dir, replace_dir
from hoh_cosim.study.sweep import Outcome, Variant, run_variants, set_option
from hoh_cosim.study.verification import Table

__all__ = ["CORRECTIONS", "ProbeSettings", "ProbeStudy", "run_probe_correction", "train_network"]

CORRECTIONS = ("raw", "network", "online")
_KIND = {"raw": "none", "network": "network", "online": "online"}
SEED_VALIDATION_R = (0.945, 0.981, 0.998)
"""The seed's validation correlations per axis (4.A)."""
_DAYS = ("day one", "day two")
_CONTACT_KEEP = (
    "plant.F_contact_B",
    "plant.penetration",
    "estimator.probe_check",
    "estimator.probe_mismatch",
    "estimator.probe_drift",
)


@dataclass(frozen=True)
class ProbeSettings:
    """Durations of the recordings and of the contact runs (the quick ones are for tests)."""

    training_s: float = 123.0
    test_s: float = 63.0
    contact_s: float | None = None  # None: the scenario's own 50 s
    max_iter: int = 3000


QUICK = ProbeSettings(training_s=43.0, test_s=23.0, contact_s=30.0, max_iter=500)


@dataclass
class Network:
    weights: np.ndarray  # the packed vector (`pack_network`)
    validation_r: list[float | None]
    test_r: list[float | None]
    split: dict[str, np.ndarray]  # row indices of the training recording: train, validation, test
    iterations: list[int]  # L-BFGS iterations per axis (at most `max_iter`)


def train_network(s: ProbeSamples, seed: int, max_iter: int = 3000) -> Network:
    """The seed's three networks, trained on 70 % of `s`; correlations on validation and test."""
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    n = len(s.t)
    if n < 20:
        raise RunError(f"probe-correction: only {n} probe samples to train on (at least 20)")
    order = np.random.default_rng(seed).permutation(n)
    split = {
        "train": order[: int(0.70 * n)],
        "validation": order[int(0.70 * n) : int(0.85 * n)],
        "test": order[int(0.85 * n) :],
    }
    x, y = s.m[split["train"]], s.reference[split["train"]]
    x_mean, x_scale = x.mean(axis=0), x.std(axis=0)
    y_mean, y_scale = y.mean(axis=0), y.std(axis=0)
    if np.any(x_scale <= 0.0) or np.any(y_scale <= 0.0):
        raise RunError("probe-correction: an axis of the training data does not vary")
    layers, iterations = [], []
    for j in range(3):
        net = MLPRegressor(
            hidden_layer_sizes=(HIDDEN,),
            activation="logistic",
            solver="lbfgs",
            max_iter=max_iter,
            random_state=seed + j,
        )
        with warnings.catch_warnings():  # an iteration budget, as the seed's training had
            warnings.simplefilter("ignore", ConvergenceWarning)
            net.fit((x - x_mean) / x_scale, (y[:, j] - y_mean[j]) / y_scale[j])
        iterations.append(int(net.n_iter_))
        W1, w2 = net.coefs_
        b1, b2 = net.intercepts_
        layers.append((W1.T, b1, w2[:, 0], float(b2[0])))
    weights = pack_network(x_mean, x_scale, y_mean, y_scale, layers)

    def r(part: str) -> list[float | None]:
        rows = split[part]
        return axis_correlation(apply_network(weights, s.m[rows]), s.reference[rows])

    return Network(weights, r("validation"), r("test"), split, iterations)


def apply_network(weights: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The networks on every row of m (n, 3): the estimator's own forward pass."""
    return np.array([network_forward(weights, row) for row in m]).reshape(-1, 3)


@dataclass
class ProbeStudy:
    out: Path
    summary: dict[str, Any]
    table: list[dict[str, Any]]
    contact: list[dict[str, Any]]


def _samples(outcome: Outcome, what: str) -> ProbeSamples:
    if not outcome.ok:
        raise RunError(f"probe-correction: the {what} recording failed: {outcome.error}")
    s = outcome.data.get("probe_samples")
    if s is None or len(s.t) < 20:
        raise RunError(f"probe-correction: the {what} recording has no probe samples")
    return s


def run_probe_correction(
    out: str | Path,
    scenarios: str | Path = "scenarios",
    *,
    seed: int = 1,
    engine: str = "inprocess",
    settings: ProbeSettings | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
) -> ProbeStudy:
    settings = settings or ProbeSettings()
    out = Path(out)
    scenarios = Path(scenarios)
    check_out_dir(out, marker="table.csv", what="probe-correction")
    data_file, contact_file = scenarios / "probe_data.yaml", scenarios / "contact_scan_online.yaml"
    for path in (data_file, contact_file):
        if not path.is_file():
            raise ConfigError(f"--scenarios {scenarios}: {path.name} not found")
    started = time.perf_counter()

    def recording(i: int, session: int, run_seed: int, duration: float) -> Variant:
        return Variant(
            i,
            str(data_file),
            (set_option("fse103.housing.session", session),),
            seed=run_seed,
            duration_s=duration,
            engine=engine,
            keep_data=True,
        )

    recordings = [
        recording(0, 1, seed, settings.training_s),
        recording(1, 1, seed + 1, settings.test_s),
        recording(2, 2, seed + 2, settings.test_s),
    ]
    got = run_variants(
        recordings, workers=workers, scheduler=scheduler, progress=progress, label="recordings"
    )
    training = _samples(got[0], "training")
    days = {"day one": _samples(got[1], "day-one"), "day two": _samples(got[2], "day-two")}
    network = train_network(training, seed, settings.max_iter)

    table: list[dict[str, Any]] = []
    curves: dict[str, dict[str, np.ndarray]] = {}
    for day, s in days.items():
        curves[day] = {"raw": s.m, "network": apply_network(network.weights, s.m)}
        curves[day]["online"] = s.corrected
        for correction, values in curves[day].items():
            table.append(
                {
                    "day": day,
                    "correction": correction,
                    "samples": len(s.t),
                    "correlation": axis_correlation(values, s.reference),
                    "rms_N": axis_rms(values - s.reference),
                }
            )

    contact_variants = []
    for d, day in enumerate(_DAYS):
        for c, correction in enumerate(CORRECTIONS):
            overrides = [set_option("fse103.housing.session", d + 1)]
            if correction == "network":  # the weights first: a network without them is refused
                overrides.append(
                    set_option("estimator.probe_correction.network", network.weights.tolist())
                )
            overrides.append(set_option("estimator.probe_correction.kind", _KIND[correction]))
            contact_variants.append(
                Variant(
                    3 * d + c,
                    str(contact_file),
                    tuple(overrides),
                    values=(("day", day), ("correction", correction)),
                    seed=seed,
                    duration_s=settings.contact_s,
                    engine=engine,
                    keep=_CONTACT_KEEP,
                )
            )
    contact_outcomes = run_variants(
        contact_variants,
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        label="contact_scan",
    )
    contact = [_contact_row(o) for o in contact_outcomes]

    summary = {
        "seed": seed,
        "engine": engine,
        "training_samples": len(training.t),
        "network": {
            "validation_correlation": network.validation_r,
            "test_correlation": network.test_r,
            "iterations": network.iterations,
            "seed_validation_correlation": list(SEED_VALIDATION_R),
        },
        "table": table,
        "contact_scan": contact,
        "wall_s": time.perf_counter() - started,
    }
    figures = {
        "fig13_regression.png": _regression_figure(training, network),
        "fig14_day_one.png": _day_figure(days["day one"], curves["day one"], "day one"),
        "fig15_day_two.png": _day_figure(days["day two"], curves["day two"], "day two"),
        "contact_scan.png": _contact_figure(contact_outcomes),
    }
    network_json = {
        "description": (
            "the seed's three probe-force networks (20 logistic neurons each), trained on day one; "
            "use with --set estimator.probe_correction.kind=network "
            "--set estimator.probe_correction.network=<weights>"
        ),
        "validation_correlation": network.validation_r,
        "weights": network.weights.tolist(),
    }

    def fill(staging: Path) -> None:
        for name, data in figures.items():
            (staging / name).write_bytes(data)
        (staging / "table.csv").write_text(_table_csv(table), encoding="utf-8")
        (staging / "summary.json").write_text(
            json.dumps(jsonable(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )
        (staging / "network.json").write_text(
            json.dumps(network_json, indent=1) + "\n", encoding="utf-8"
        )
        (staging / "report.md").write_text(_markdown(summary, figures), encoding="utf-8")

    replace_dir(out, fill, what="probe-correction")
    return ProbeStudy(out, summary, table, contact)


def _contact_row(o: Outcome) -> dict[str, Any]:
    row: dict[str, Any] = dict(o.variant.values)
    if not o.ok:
        return {**row, "status": "failed", "error": o.error}
    m = o.metrics
    row.update(
        status="ok",
        contact_losses=m.get("contact_losses"),
        contact_force_mean_N=m.get("contact_force_mean_N"),
        contact_force_std_N=m.get("contact_force_std_N"),
        max_bounce_m=m.get("max_bounce_m"),
        controller_flags=m.get("controller_flags"),
        controller_stop_s=m.get("controller_stop_s"),
    )
    after = _after_check(o)
    mismatch = o.signals["estimator.probe_mismatch"][after, 0]
    drift = o.signals["estimator.probe_drift"][after, 0]
    row["mismatch_max_N"] = float(mismatch.max()) if mismatch.size else None
    row["drift_flagged_fraction"] = float(np.mean(drift > 0.5)) if drift.size else None
    return row


def _after_check(o: Outcome) -> np.ndarray:
    """The kept rows once the probe check is over (and the estimator rebiased)."""
    check = o.signals["estimator.probe_check"][:, 0] > 0.5
    if not check.any():
        return np.zeros(len(check), dtype=bool)
    end = int(np.flatnonzero(check)[-1]) + 1
    after = np.zeros(len(check), dtype=bool)
    after[end:] = True
    return after


def _table_csv(table: list[dict[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    header = ["day", "correction", "samples"]
    header += [f"correlation_{a}" for a in "xyz"] + [f"rms_{a}_N" for a in "xyz"]
    writer.writerow(header)
    for row in table:
        writer.writerow(
            [row["day"], row["correction"], row["samples"]]
            + [_number(v) for v in row["correlation"] + row["rms_N"]]
        )
    return buffer.getvalue()


def _number(value: float | None) -> str:
    return "" if value is None or not math.isfinite(value) else repr(float(value))


def _f(value: Any, fmt: str = ".3g") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, list | tuple):
        return " / ".join(_f(v, fmt) for v in value)
    return format(value, fmt) if isinstance(value, float) else str(value)


def _markdown(summary: dict[str, Any], figures: dict[str, bytes]) -> str:
    net = summary["network"]
    lines = [
        "# Probe-force correction: the seed's network, its day-two failure, the online map\n",
        f"Seed {summary['seed']}, engine {summary['engine']}, {summary['wall_s']:.0f} s. The "
        "reference is the compensated wrist force while the hand, off the handle, presses the "
        "probe tip (seed Fig. 6 and 14); all axes are the probe sensor's (P).\n",
        f"Network (3 x 20 logistic neurons, {summary['training_samples']} samples from day one): "
        f"validation correlation {_f(net['validation_correlation'])}, test "
        f"{_f(net['test_correlation'])}; the seed's validation {_f(net['seed_validation_correlation'])}.\n",
    ]
    rows = [
        [
            r["day"],
            r["correction"],
            _f(r["correlation"]),
            _f(r["rms_N"]),
        ]
        for r in summary["table"]
    ]
    lines.append(
        Table(
            "Against the wrist: correlation and RMS error [N] per axis x / y / z",
            ["day", "correction", "correlation", "RMS error [N]"],
            rows,
        ).markdown()
    )
    contact_rows = []
    for r in summary["contact_scan"]:
        if r["status"] != "ok":
            contact_rows.append([r["day"], r["correction"], f"failed: {r['error']}"] + [""] * 6)
            continue
        contact_rows.append(
            [
                r["day"],
                r["correction"],
                _f(r["contact_losses"]),
                _f(r["contact_force_mean_N"]),
                _f(r["contact_force_std_N"]),
                _f(1e3 * r["max_bounce_m"] if r["max_bounce_m"] is not None else None),
                _f(r["mismatch_max_N"]),
                _f(r["drift_flagged_fraction"]),
                r["controller_flags"],
            ]
        )
    lines.append(
        Table(
            "contact_scan_online with each correction in the loop (contact compensation, eq. 12)",
            [
                "day",
                "correction",
                "contact losses",
                "force mean [N]",
                "force std [N]",
                "max bounce [mm]",
                "mismatch max [N]",
                "drift flagged (fraction)",
                "controller flags",
            ],
            contact_rows,
        ).markdown()
    )
    lines += [f"![{name}]({name})\n" for name in figures]
    return "\n".join(lines)


def _regression_figure(s: ProbeSamples, network: Network) -> bytes:
    """The seed's Fig. 13: network output against target per axis, validation and test."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for j, ax in enumerate(axes):
        for part, colour, r in (
            ("validation", "tab:green", network.validation_r[j]),
            ("test", "tab:red", network.test_r[j]),
        ):
            rows = network.split[part]
            predicted = apply_network(network.weights, s.m[rows])[:, j]
            ax.plot(
                s.reference[rows, j], predicted, ".", ms=2, color=colour, label=f"{part} R={_f(r)}"
            )
        lo, hi = float(s.reference[:, j].min()), float(s.reference[:, j].max())
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set_title(f"{'xyz'[j]}: seed R={SEED_VALIDATION_R[j]}")
        ax.set_xlabel("target (wrist) [N]")
        ax.set_ylabel("network output [N]")
        ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    return png(fig)


def _day_figure(s: ProbeSamples, curves: dict[str, np.ndarray], day: str) -> bytes:
    """The seed's Fig. 14 / 15: the first 20 s of pushes."""
    rows = s.t <= s.t[0] + 20.0
    fig = probe_forces_figure(
        s.t[rows],
        s.reference[rows],
        {k: v[rows] for k, v in curves.items()},
        f"{day}: wrist, raw probe, day-one network, online map",
    )
    return png(fig)


def _contact_figure(outcomes: list[Outcome]) -> bytes:
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    for ax, day in zip(axes, _DAYS, strict=True):
        for o in outcomes:
            values = dict(o.variant.values)
            if values["day"] != day or not o.ok or o.time is None:
                continue
            force = o.signals["plant.F_contact_B"][:, 2]
            ax.plot(o.time, force, lw=0.9, label=values["correction"])
        ax.set_ylabel("contact force z [N]")
        ax.set_title(f"{day}: contact_scan_online with each correction in the loop")
        ax.legend(fontsize=8, loc="upper left")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    return png(fig)
