"""The documentation's results pages, rendered from the runs' own outputs, never typed in.

    python -m hoh_cosim.docsite results [--quick] [--seeds 13 17] [--operators 20]
                                        [--skip-report] [--skip-clinical]

re-measures them: `hoh-cosim report` (the seed's experiments, the seed's figures beside ours) into
`docs/results/data/report/` (its `report.md`, `summary.json` and figures), and `hoh-cosim study
clinical` with the `seed` and `clinical` presets on each seed into
`docs/results/data/clinical/seed-S.json` (the study's `summary.json`). The site's build hook renders
`results/seed.md` and `results/clinical.md` from those files at every build.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

from hoh_cosim.study.clinical import TARGETS

__all__ = ["DATA", "measure", "pages"]

DATA = Path(__file__).resolve().parents[3] / "docs" / "results" / "data"
"""Where the measured outputs are kept, in a checkout."""

_REPORT_FILES = ("report.md", "summary.json")


def pages(data: Path = DATA) -> dict[str, str]:
    return {"results/seed.md": seed_page(data), "results/clinical.md": clinical_page(data)}


def _provenance(data: Path, what: str) -> str:
    stamp = data / what / "measured.json"
    if not stamp.is_file():
        return "Not measured yet: run `python -m hoh_cosim.docsite results`."
    info = json.loads(stamp.read_text(encoding="utf-8"))
    return (
        f"Measured by `{info['command']}` with hoh-cosim {info['version']} on {info['date']}; "
        "this page is rendered from the outputs it kept."
    )


def seed_page(data: Path = DATA) -> str:
    report = data / "report" / "report.md"
    lines = [
        "# The seed's figures against ours",
        "",
        "The seed's experiments (seed 000, Fig. 16-21) as reproducible runs, the seed's own "
        "numbers quoted beside ours, the linear analysis and the tuning that beats the seed: "
        "the verification report of `hoh-cosim report`.",
        "",
        _provenance(data, "report"),
        "",
    ]
    if report.is_file():
        body = report.read_text(encoding="utf-8").split("\n", 1)[1]  # its own title
        body = body.replace("](", "](data/report/").replace("](data/report/http", "](http")
        lines.append(body.replace("\n## ", "\n## ").strip())
    return "\n".join(lines) + "\n"


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{value:.0f} %"


def _met(flag: bool | None) -> str:
    return {True: "met", False: "**missed**", None: "not judged"}[flag]


def clinical_page(data: Path = DATA) -> str:
    lines = [
        "# The clinical study",
        "",
        "Simulated sonographers (a population drawn from a seed: hand, tremor, strength, grip; a "
        "breathing patient each) reach a view and hold it, scan a 10 cm line at 8 N, press to "
        "15 N and hold a view while the patient moves away, freehand and assisted; every figure "
        "is a paired comparison per operator against freehand (`hoh-cosim study clinical`, "
        "[the tutorial](../tutorials/clinical-study.md)). The presets were tuned on seeds 1 to 3; "
        "the seeds below were picked before they were looked at.",
        "",
        _provenance(data, "clinical"),
        "",
        "## The targets",
        "",
        "| target | value |",
        "|---|---|",
        "| hand force less than freehand, every operator | "
        + ", ".join(f"{t} ≥ {v:.0f} %" for t, v in TARGETS["hand_force_reduction_pct"].items())
        + " |",
        f"| image jitter better than freehand, mean per task | ≥ "
        f"{TARGETS['jitter_improvement_pct']:.0f} % |",
        f"| hands-off contact force std in every hold | ≤ "
        f"{TARGETS['hold_contact_force_std_N']} N, no contact lost |",
        f"| after the patient moves away | contact back within {TARGETS['recovery_time_s']:g} s, "
        f"never above {TARGETS['recovery_peak_N']:g} N |",
        f"| release on `scenarios/release.yaml` | drift ≤ {TARGETS['release_drift_m'] * 1e3:g} mm, "
        f"settled within {TARGETS['release_settle_s'] * 1e3:g} ms |",
        "",
    ]
    for path in sorted((data / "clinical").glob("seed-*.json")):
        summary = json.loads(path.read_text(encoding="utf-8"))
        lines += _clinical_section(path.stem.removeprefix("seed-"), summary)
    return "\n".join(lines) + "\n"


def _clinical_section(seed: str, summary: dict[str, Any]) -> list[str]:
    operators = summary.get("operators", "?")
    lines = [
        f"## Population seed {seed} ({operators} operators)",
        "",
        "| preset | hand force less, smallest (view, scan, press) | jitter better, mean "
        "(view, scan, press) | hold std, largest | contact back, slowest | release |",
        "|---|---|---|---|---|---|",
    ]
    release = summary.get("release", {})
    for mode, entry in summary.get("targets", {}).items():
        effort = entry["hand_force_reduction_pct_smallest"]
        jitter = entry["jitter_improvement_pct_mean"]
        std = entry.get("hold_contact_force_std_N_largest")
        hold = "—" if std is None else f"{std:.2f} N: {_met(entry.get('hold_met'))}"
        back = entry.get("recovery_time_s_largest")
        never = entry.get("recovery_never_back") or 0
        recovery = (
            f"never back in {never} runs"
            if never
            else (
                "—" if back is None else f"{back:.2f} s, {entry['recovery_peak_N_largest']:.1f} N"
            )
        )
        drift = (release.get(mode) or {}).get("drift_m")
        settle = (release.get(mode) or {}).get("settle_s")
        released = (
            "—"
            if drift is None
            else f"{drift * 1e3:.2f} mm, "
            + ("never settled" if settle is None else f"{settle * 1e3:.0f} ms")
        )
        lines.append(
            f"| `{mode}` | {', '.join(_pct(effort[t]) for t in effort)}: "
            f"{_met(entry['hand_force_reduction_met'])} | "
            f"{', '.join(_pct(jitter[t]) for t in jitter)}: {_met(entry['jitter_improvement_met'])}"
            f" | {hold} | {recovery}: {_met(entry.get('recovery_met'))} | {released}: "
            f"{_met(entry.get('release_met'))} |"
        )
    return [*lines, ""]


def _without_operators(summary: Any) -> Any:
    """The study's summary without its per-operator lists (a third of the size; the pages show
    the statistics over the operators)."""
    if isinstance(summary, dict):
        return {k: _without_operators(v) for k, v in summary.items() if k != "per_operator"}
    if isinstance(summary, list):
        return [_without_operators(v) for v in summary]
    return summary


def measure(
    data: Path = DATA,
    *,
    quick: bool = False,
    seeds: tuple[int, ...] = (13, 17),
    operators: int = 20,
    report: bool = True,
    clinical: bool = True,
) -> None:
    """Run the report and the clinical study, and keep what the pages are rendered from."""
    import datetime

    from hoh_cosim import __version__, cli

    def stamp(where: Path, command: str) -> None:
        info = {
            "command": command,
            "version": __version__,
            "date": datetime.date.today().isoformat(),
        }
        (where / "measured.json").write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")

    with tempfile.TemporaryDirectory() as scratch:
        if report:
            argv = ["report", "--out", f"{scratch}/report", *(["--quick"] if quick else [])]
            if cli.main(argv) != 0:
                raise SystemExit("the report failed")
            target = data / "report"
            shutil.rmtree(target, ignore_errors=True)
            target.mkdir(parents=True)
            for item in Path(scratch, "report").iterdir():
                if item.name in _REPORT_FILES or item.suffix == ".png":
                    shutil.copy2(item, target / item.name)
            stamp(target, "hoh-cosim report" + (" --quick" if quick else ""))
        if clinical:
            target = data / "clinical"
            target.mkdir(parents=True, exist_ok=True)
            for seed in seeds:
                argv = [
                    "study",
                    "clinical",
                    *(["--quick"] if quick else []),
                    *("--operators", str(operators), "--seed", str(seed)),
                    *("--preset", "seed", "--preset", "clinical"),
                    *("--out", f"{scratch}/clinical-{seed}", "--quiet"),
                ]
                if cli.main(argv) != 0:
                    raise SystemExit(f"the clinical study on seed {seed} failed")
                summary = json.loads(
                    Path(scratch, f"clinical-{seed}", "summary.json").read_text(encoding="utf-8")
                )
                (target / f"seed-{seed}.json").write_text(
                    json.dumps(_without_operators(summary), indent=1) + "\n", encoding="utf-8"
                )
            stamp(
                target,
                f"hoh-cosim study clinical --operators {operators} --seed S --preset seed "
                "--preset clinical, S = " + ", ".join(map(str, seeds)),
            )
