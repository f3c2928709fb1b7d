"""The run plots: every title says its time window and frame, legends never cover data, commanded
and actual are drawn apart, the lag sign is defined, long series are decimated without losing
their extremes."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.text import Text

from hoh_cosim.calibration import read_poses_csv
from hoh_cosim.control.gravity import GRAVITY_B, identify_gravity
from hoh_cosim.cosim import plots
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.report import compute_report
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
PNG = b"\x89PNG\r\n\x1a\n"

# one scenario per metric set that simulates quickly, long enough for its metrics
RUNS = {
    "circles": 12.0,
    "static_noise": 5.0,
    "contact_scan": 12.0,
    "release": 8.0,
    "teleecho_slide": 8.0,
    "teleecho_slide_ur5": 8.0,
    "probe_data": 8.0,
}
WINDOW = re.compile(r"t = \d+\.\d–\d+\.\d s( of \d+(\.\d+)? s|, \d+ probe packets)")
FRAME = re.compile(r"frame [BSPd]\b|joint space")


@pytest.fixture(scope="module")
def runs():
    out = {}
    for name, duration in RUNS.items():
        scenario = load_scenario(SCENARIOS / f"{name}.yaml", duration_s=duration)
        rec = simulate(scenario, "inprocess", progress=False)
        out[name] = (scenario, rec, compute_report(scenario, rec))
    return out


@pytest.fixture(scope="module")
def gravity_figure():
    R_BS, wrench = read_poses_csv(ROOT / "tests" / "data" / "poses_seed_tool.csv")
    cal = identify_gravity(R_BS, wrench, GRAVITY_B)
    return plots.gravity_residual_figure(
        cal, R_BS, wrench, GRAVITY_B, window="poses held over t = 3.5–272.0 s of 272 s"
    )


def all_figures(runs, gravity_figure):
    figs = {"gravity_calibration/gravity_residuals.png": gravity_figure}
    for name, run in runs.items():
        for file, fig in plots.figures(*run).items():
            figs[f"{name}/{file}"] = fig
    return figs


EXPECTED = {
    "circles": {"path.png", "hand_force.png", "velocity.png"},
    "static_noise": {"noise.png"},
    "contact_scan": {"contact.png", "velocity.png"},
    "release": {"release.png"},
    "teleecho_slide": {"pose_error.png", "torques.png"},
    "teleecho_slide_ur5": {"pose_error.png", "command.png"},
    "probe_data": {"probe_forces.png"},
}


@pytest.mark.parametrize("name", RUNS)
def test_each_scenario_renders_its_figures_as_png(runs, name):
    images = plots.render_plots(*runs[name])
    assert set(images) == EXPECTED[name]
    for data in images.values():
        assert data.startswith(PNG)


def test_every_title_says_the_time_window_and_the_frame(runs, gravity_figure):
    for name, fig in all_figures(runs, gravity_figure).items():
        title = fig.get_suptitle()
        assert WINDOW.search(title), f"{name}: no time window in {title!r}"
        assert FRAME.search(title), f"{name}: no frame in {title!r}"


def test_the_path_names_its_plane_and_the_metrics_window(runs):
    fig = plots.figures(*runs["circles"])["path.png"]
    title = fig.get_suptitle()
    assert "x–y plane of the base frame B, seen from +z" in title
    # 12 s: the ramp ends at 4 s, two whole 4 s circles fit
    assert "t = 4.0–12.0 s of 12 s" in title
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x in B [mm]"
    assert ax.get_ylabel() == "y in B [mm]"


def _boxes_overlap(a, b) -> bool:
    return min(a.x1, b.x1) - max(a.x0, b.x0) > 0.5 and min(a.y1, b.y1) - max(a.y0, b.y0) > 0.5


def test_legends_and_titles_lie_outside_the_data_and_inside_the_figure(runs, gravity_figure):
    for name, fig in all_figures(runs, gravity_figure).items():
        renderer = fig.canvas.get_renderer()
        fig.canvas.draw()
        panels = [ax.get_window_extent(renderer) for ax in fig.axes]
        legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)
        assert legends, f"{name}: no legend"
        title = [t for t in fig.findobj(Text) if t.get_text() == fig.get_suptitle()]
        texts = title + list(fig.texts)
        assert title, f"{name}: no title"
        boxes = [legend.get_window_extent(renderer) for legend in legends]
        for i, box in enumerate(boxes):
            for other in boxes[i + 1 :]:
                assert not _boxes_overlap(box, other), f"{name}: two legends overlap"
        for artist in legends + texts:
            box = artist.get_window_extent(renderer)
            for panel in panels:
                assert not _boxes_overlap(box, panel), f"{name}: {artist} covers a panel"
            inside = fig.bbox.padded(0.5)
            assert inside.contains(box.x0, box.y0), f"{name}: {artist} cut off"
            assert inside.contains(box.x1, box.y1), f"{name}: {artist} cut off"


def test_every_axis_has_a_unit(runs, gravity_figure):
    for name, fig in all_figures(runs, gravity_figure).items():
        for ax in fig.axes:
            assert re.search(r"\[.+\]", ax.get_ylabel()), f"{name}: {ax.get_ylabel()!r}"
            if ax.get_xlabel():
                unit = re.search(r"\[.+\]", ax.get_xlabel()) or ax.get_xlabel() == "pose number"
                assert unit, f"{name}: {ax.get_xlabel()!r}"


def test_commanded_is_black_dashed_over_a_solid_actual_with_a_difference_panel(runs):
    fig = plots.figures(*runs["circles"])["velocity.png"]
    for ax in fig.axes[:3]:
        lines = {line.get_label(): line for line in ax.get_lines()}
        commanded, actual = lines["commanded"], lines["actual"]
        assert (commanded.get_linestyle(), commanded.get_color()) == ("--", "k")
        assert actual.get_linestyle() == "-"
        assert actual.get_color() != "k"
        assert commanded.get_zorder() >= actual.get_zorder()
    difference = fig.axes[3]
    assert difference.get_ylabel().startswith("actual − cmd")
    assert [line.get_label() for line in difference.get_lines()] == ["x", "y", "z"]


def test_the_hand_force_figure_shows_1_s_and_defines_the_lag_sign(runs):
    scenario, rec, report = runs["circles"]
    fig = plots.figures(scenario, rec, report)["hand_force.png"]
    lo, hi = fig.axes[0].get_xlim()
    assert hi - lo == pytest.approx(1.0)
    title = fig.get_suptitle()
    assert f"t = {lo:.1f}–{hi:.1f} s of 12 s" in title
    lag = report.metrics["filter_lag_ms"]
    assert f"filter_lag_ms = {lag:+.3g} ms".replace("-", "−") in title
    note = " ".join(text.get_text().replace("\n", " ") for text in fig.texts)
    assert "> 0 late, < 0 ahead" in note
    assert "filter_lag_ms: the filtered estimate behind the measured (held) force" in note
    assert "estimate_lag_ms: the filtered estimate behind the true hand force" in note


def test_every_line_is_decimated_to_the_bound(runs, gravity_figure):
    for name, fig in all_figures(runs, gravity_figure).items():
        for ax in fig.axes:
            for line in ax.get_lines():
                assert len(line.get_xdata()) <= plots.MAX_POINTS, f"{name}: {line.get_label()}"


@pytest.mark.parametrize("n", [10, 4000, 4001, 30_001, 272_001])
@pytest.mark.parametrize("max_points", [50, 1000, 4000])
def test_minmax_indices_keep_the_extremes_and_the_ends_within_the_bound(rng, n, max_points):
    y = np.cumsum(rng.normal(size=n)) + rng.normal(scale=5.0, size=n)
    y[rng.integers(n)] = 1e3  # a spike
    y[rng.integers(n)] = -1e3
    rows = plots.minmax_indices(y, max_points)
    assert len(rows) == n if n <= max_points else len(rows) <= max_points
    assert np.all(np.diff(rows) > 0)
    assert (rows[0], rows[-1]) == (0, n - 1)
    assert (y[rows].min(), y[rows].max()) == (y.min(), y.max())


def test_minmax_indices_share_rows_across_columns_and_skip_nans(rng):
    path = np.column_stack([np.cos(np.linspace(0, 60, 50_001)), np.sin(np.linspace(0, 60, 50_001))])
    path[1000:2000] = np.nan
    rows = plots.minmax_indices(path, 4000)
    assert len(rows) <= 4000
    np.testing.assert_array_equal(np.nanmax(path[rows], axis=0), np.nanmax(path, axis=0))
    np.testing.assert_array_equal(np.nanmin(path[rows], axis=0), np.nanmin(path, axis=0))


def test_minmax_indices_refuse_a_bound_too_small_for_the_columns():
    with pytest.raises(ConfigError, match=r"max_points: expected >= 14 for 3 columns, got 10"):
        plots.minmax_indices(np.zeros((100, 3)), 10)


def test_png_closes_a_pyplot_figure_too():
    plt = plots.pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    assert plots.png(fig).startswith(PNG)
    assert fig.number not in plt.get_fignums()


def test_render_plots_does_not_import_pyplot():
    code = (
        "import sys\n"
        "from hoh_cosim.cosim.engines import simulate\n"
        "from hoh_cosim.cosim.plots import render_plots\n"
        "from hoh_cosim.cosim.report import compute_report\n"
        "from hoh_cosim.cosim.scenario import load_scenario\n"
        f"s = load_scenario({str(SCENARIOS / 'release.yaml')!r}, duration_s=1.0)\n"
        "r = simulate(s, 'inprocess', progress=False)\n"
        "assert render_plots(s, r, compute_report(s, r))\n"
        "print('matplotlib.pyplot' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_the_plots_benchmark_prints_its_figures_as_json():
    result = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "plots_speed.py"),
            *("--scenarios", "release", "--duration", "2", "--repeats", "1"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["release_rows"] == 2001
    assert figures["release_images"] == 1
    assert figures["matplotlib_import_s"] > 0
    assert figures["release_render_s"] > 0


@pytest.mark.parametrize(
    ("name", "duration"),
    [
        ("circles", 6.0),  # not one whole circle after the ramp
        ("static_noise", 2.0),  # still rebiasing
        ("contact_scan", 3.0),  # never touches
        ("release", 4.0),  # never lets go
        ("teleecho_slide", 2.0),  # before the approach
        ("probe_data", 1.0),  # no probe packet checked yet
    ],
)
def test_a_run_too_short_for_its_metrics_still_plots_and_says_n_a(name, duration):
    scenario = load_scenario(SCENARIOS / f"{name}.yaml", duration_s=duration)
    rec = simulate(scenario, "inprocess", progress=False)
    report = compute_report(scenario, rec)
    figs = plots.figures(scenario, rec, report)
    for fig in figs.values():
        assert WINDOW.search(fig.get_suptitle())
    assert all(data.startswith(PNG) for data in plots.render_plots(scenario, rec, report).values())
