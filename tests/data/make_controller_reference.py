"""Make `controller_reference.json` and `controller_reference.npz`: what the hand-guiding controller
commanded, tick by tick, in every scenario that has one and in the clinical study's modes.

    python tests/data/make_controller_reference.py            # writes both files
    python tests/data/make_controller_reference.py --runs     # writes only the run list (JSON)
    python tests/data/make_controller_reference.py --signals-only --out FILE.npz
                                                  # records the listed runs' signals into FILE

The run list (`controller_reference.json`) is each run's scenario, `--set` overrides, seed and
duration, written out literally so that the runs stay what they were whatever the project's code
and presets become. The clinical study's runs are one operator's (the study's seed 1, operator 1),
each mode's `--quick` task, with the overrides the study gave them when this file was made: the
study's code of that time makes them, so the script runs on that commit (5d17755, in a git
worktree with this file copied in).

The signals (`controller_reference.npz`), per run `NAME`: `NAME/twist_B` and `NAME/twist_law_B`
(every controller tick), `NAME/status` and `NAME/brake_accel` (every controller tick) and
`NAME/p_BT_B` (the plant's tip, every 20 ms). They were recorded in-process from main before the
controller became a mode machine over stages (issue 51); `tests/unit/test_controller_equivalence.py`
runs the same list and compares.

The signals are recorded with OpenBLAS's Haswell kernels on one thread (`BLAS_ENV`; the script
starts itself again with them when they are not set): OpenBLAS picks its kernels by the CPU it
runs on, and the SkylakeX and the Zen kernels round a small product differently in the last bit,
which a contact's loop amplifies to 1e-5 of a twist's peak within seconds. The Haswell kernels
need AVX2 and FMA, which every x86-64 machine of the last decade has; the comparison runs with
the same environment. The first recording (commit 5d17755's code, on an Intel machine) took
OpenBLAS's own choice, SkylakeX; it was recorded again from the same commit with `BLAS_ENV`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
RUNS = HERE / "controller_reference.json"
SIGNALS = HERE / "controller_reference.npz"
TIP_EVERY = 20  # master ticks between the tip's kept samples
BLAS_ENV = {"OPENBLAS_CORETYPE": "Haswell", "OPENBLAS_NUM_THREADS": "1"}
"""OpenBLAS's kernels and threads the signals are recorded with (read once, when numpy loads)."""


def _study_runs() -> list[dict]:
    """The clinical study's runs of one operator (made from the study's code as it was)."""
    from hoh_cosim.study.clinical import MODES, study_variants

    wanted = {
        ("transparency", "scan"),
        ("checked", "press"),
        ("hold", "view"),
        ("hold", "press"),
        ("follow", "scan"),
        ("glide", "scan"),
        ("glide", "view"),
    }
    out = []
    for (_, task, mode), variant in study_variants(ROOT / "scenarios", 1, 1, True, MODES):
        if (mode, task) in wanted:
            out.append(
                {
                    "name": f"study_{mode}_{task}",
                    "scenario": Path(variant.scenario).name,
                    "overrides": list(variant.overrides),
                    "seed": variant.seed,
                    "duration_s": variant.duration_s,
                }
            )
    hold_view = next(r for r in out if r["name"] == "study_hold_view")
    # a hold allowed 4 mm only: its travel guard ends it, the robot rests, the hand takes over
    out.append(
        {
            **hold_view,
            "name": "study_hold_view_travel",
            "overrides": [*hold_view["overrides"], "controller.hold.max_travel_m=0.004"],
        }
    )
    # hold, glide and the follow together (never a study mode before the presets), letting go
    glide = next(r for r in out if r["name"] == "study_glide_view")
    extra = [o for o in glide["overrides"] if o not in hold_view["overrides"]]
    for task in ("view", "press"):
        base = next(r for r in out if r["name"] == f"study_hold_{task}")
        out.append({**base, "name": f"study_all_{task}", "overrides": [*base["overrides"], *extra]})
    return out


def make_runs() -> list[dict]:
    from hoh_cosim.cosim.scenario import load_scenario

    runs = []
    for path in sorted((ROOT / "scenarios").glob("*.yaml")):
        scenario = load_scenario(path)
        if scenario.component_of_kind("controller") is None:
            continue
        runs.append(
            {
                "name": path.stem,
                "scenario": path.name,
                "overrides": [],
                "seed": None,
                "duration_s": None,
            }
        )
    # the release brake, the variable law, the passivity controller and the lead-lag filter
    runs.append(
        {
            "name": "release_transparency",
            "scenario": "release.yaml",
            "overrides": [
                "estimator.filter=lead_lowpass",
                "controller.translation.law=variable",
                "controller.release.enabled=true",
                "controller.passivity.enabled=true",
            ],
            "seed": None,
            "duration_s": None,
        }
    )
    # the same laws in contact, with the fixture along the contact's normal
    runs.append(
        {
            "name": "contact_scan_transparency",
            "scenario": "contact_scan.yaml",
            "overrides": [
                *runs[-1]["overrides"],
                "controller.virtual_fixture=true",
                "controller.fixture_normal=contact",
            ],
            "seed": None,
            "duration_s": None,
        }
    )
    return runs + _study_runs()


def record(run: dict, preset: str | None = None) -> dict[str, np.ndarray]:
    """One run's controller outputs at its own ticks, and the plant's tip; `preset`: the one the
    run is loaded with (the code before presets had none: the blocks' defaults, the seed's law)."""
    from hoh_cosim.cosim.engines import simulate
    from hoh_cosim.cosim.scenario import load_scenario

    path = ROOT / "scenarios" / run["scenario"]
    args = (path, run["overrides"], run["duration_s"], run["seed"])
    scenario = load_scenario(*args) if preset is None else load_scenario(*args, preset)
    every = scenario.components["controller"].every
    rec = simulate(scenario, "inprocess", progress=False)
    ticks = slice(every - 1, None, every)  # the controller's outputs, held from its step on
    out = {
        f"{run['name']}/{port}": np.array(rec[f"controller.{port}"][ticks])
        for port in ("twist_B", "twist_law_B", "status", "brake_accel")
    }
    out[f"{run['name']}/p_BT_B"] = np.array(rec["plant.p_BT_B"][::TIP_EVERY])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", action="store_true", help="write only the run list")
    parser.add_argument(
        "--signals-only", action="store_true", help="record the listed runs, keep the run list"
    )
    parser.add_argument("--out", type=Path, default=SIGNALS, help="where the signals go")
    parser.add_argument(
        "--preset", default=None, help="the preset the runs are loaded with (none before presets)"
    )
    args = parser.parse_args(argv)
    if any(os.environ.get(k) != v for k, v in BLAS_ENV.items()):
        os.execve(sys.executable, [sys.executable, *sys.argv], {**os.environ, **BLAS_ENV})
    if args.signals_only:
        runs = json.loads(RUNS.read_text())
    else:
        runs = make_runs()
        RUNS.write_text(json.dumps(runs, indent=1) + "\n")
        if args.runs:
            return 0
    arrays: dict[str, np.ndarray] = {}
    for run in runs:
        print(run["name"], file=sys.stderr, flush=True)
        arrays.update(record(run, args.preset))
    np.savez_compressed(args.out, **arrays)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
