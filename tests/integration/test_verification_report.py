"""`hoh-cosim report --quick`: every section from real runs on a local Dask cluster, and the numbers
that the report promises."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cli import main
from hoh_cosim.study.verification import FULL, QUICK, _filter_settings
from tests.integration.test_scenarios import SCENARIOS

PNG = b"\x89PNG\r\n\x1a\n"

# one worker runs this module (tests/xdist_groups.py): the report is made once
pytestmark = pytest.mark.xdist_group(__name__)


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report") / "r"
    status = main(
        [
            "report",
            "--quick",
            "--workers",
            "2",
            "--scenarios",
            str(SCENARIOS),
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert status == 0
    return out


def test_every_file_is_there(report: Path) -> None:
    for name in (
        "pareto.png",
        "admittance.png",
        "gravity_residuals_nocable.png",
        "gravity_residuals_cable.png",
        "gravity_radar.png",
        "contact.png",
        "release.png",
        "bode.png",
        "margins.png",
        "tuning.png",
    ):
        assert (report / name).read_bytes().startswith(PNG), name
        assert f"src='{name}'" in (report / "index.html").read_text(encoding="utf-8")
    md = (report / "report.md").read_text(encoding="utf-8")
    for title in (
        "## 1. Noise versus lag",
        "## 2. Linear versus sigmoid admittance",
        "## 3. Gravity compensation",
        "## 4. Contact",
        "## 5. Release inertia",
        "## 6. Linear analysis",
        "## Tuning that beats the seed",
        "## 7. Seed versus us",
        "## 8. The laws side by side",
    ):
        assert title in md
    # the seed's own figures, quoted beside ours
    assert "| max abs noise before, x/y/z [N] | 1.15/1.06/0.31 |" in md
    assert "| -mg [N], with cable | -4.7631 (scale: 0.48 kg) |" in md
    assert (report / "runs.csv").is_file()


def test_the_numbers(report: Path) -> None:
    s = json.loads((report / "summary.json").read_text(encoding="utf-8"))
    assert s["failed_runs"] == []
    d = s["default"]
    # the defaults beat the seed: >= 3x attenuation with a lead, not a 10 ms lag
    assert d["beats_seed"] is True
    assert d["attenuation_min"] > 3.0
    # python-control's model of the filter predicts the lag the circles run measures
    assert d["filter_lag_ms"] == pytest.approx(s["linear_lag_ms"]["kalman ×1"], abs=0.5)
    assert s["linear_lag_ms"]["butterworth 5 Hz"] == pytest.approx(103.0, abs=1.0)
    assert 1.4 < d["gain_margin"] < 1.7
    tuned = s["tuned"]
    assert tuned is not None
    assert tuned["beats_seed"] is True
    assert tuned["gain_margin"] >= 2.0


def test_the_stability_prediction_holds_in_simulation(report: Path) -> None:
    """Above the critical slope python-control predicts, the loop oscillates: the tip's velocity
    above 1 Hz grows several times over what it is below it."""
    import csv

    with (report / "runs.csv").open(encoding="utf-8") as f:
        rows = {r["tag"]: r for r in csv.DictReader(f)}
    below = float(rows["stability|0.8"]["velocity_hf_rms_m_s"])
    above = float(rows["stability|1.25"]["velocity_hf_rms_m_s"])
    assert above > 2.0 * below


def test_the_laws_side_by_side(report: Path) -> None:
    """Section 8: the new laws brake after a release (shorter settling than the seed's law), and
    the stiff, slow operator oscillates with the seed's law but not with the variable law."""
    import csv

    with (report / "runs.csv").open(encoding="utf-8") as f:
        rows = {r["tag"]: r for r in csv.DictReader(f)}
    seed, new = "laws|seed law (defaults)", "laws|new laws, seed gains"
    for law in (seed, new, "laws|new laws, tuned gains"):
        for what in ("circles.yaml", "release.yaml", "contact_scan.yaml"):
            assert rows[f"{law}|{what}"]["status"] == "ok", (law, what)
    settle = float(rows[f"{seed}|release.yaml"]["release_settle_s"])
    assert float(rows[f"{new}|release.yaml"]["release_settle_s"]) < 0.5 * settle
    # over the last circle: a sustained oscillation (tens of mm/s) against one stopped
    shaky = float(rows[f"{seed}|population|3000|0.25"]["velocity_hf_late_rms_m_s"])
    calm = float(rows[f"{new}|population|3000|0.25"]["velocity_hf_late_rms_m_s"])
    assert shaky > 0.02 > 0.005 > calm


def test_contact_compensation_and_the_housing(report: Path) -> None:
    import csv

    with (report / "runs.csv").open(encoding="utf-8") as f:
        rows = {r["tag"]: r for r in csv.DictReader(f)}
    for tag in ("contact|eq. 12|True", "contact|virtual fixture|False"):
        assert rows[tag]["contact_losses"] == "0", tag


@pytest.mark.parametrize("settings", [QUICK, FULL])
def test_every_release_setting_is_a_compared_filter(settings) -> None:
    labels = _filter_settings(settings, np.ones(3))
    assert set(settings.release_settings) <= set(labels)
    assert "kalman ×1" in labels


def test_a_directory_that_is_not_a_report_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "notes.txt").write_text("mine", encoding="utf-8")
    assert main(["report", "--quick", "--out", str(tmp_path)]) == 2
    assert "holds no report.md" in capsys.readouterr().err
    assert (tmp_path / "notes.txt").read_text(encoding="utf-8") == "mine"


def test_missing_scenarios_are_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["report", "--quick", "--scenarios", str(tmp_path), "--out", str(tmp_path / "r")]) == 2
    )
    err = capsys.readouterr().err
    assert f"--scenarios {tmp_path}: no circles.yaml there" in err
