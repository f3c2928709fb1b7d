"""Each closed set is defined once: the modules that dispatch over it cover exactly that set."""

from __future__ import annotations

from pathlib import Path

import pytest

from hoh_cosim.control.block import TWIST_UNITS
from hoh_cosim.control.estimator import FILTER_KINDS, EstimatorParams
from hoh_cosim.cosim import plots, report
from hoh_cosim.cosim.scenario import (
    METRIC_SETS,
    TELEECHO_ARMS,
    TELEECHO_CONTROLLERS,
    load_scenario,
)
from hoh_cosim.kinds import KINDS
from hoh_cosim.study import linear

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def test_twist_units_are_m_per_s_then_rad_per_s() -> None:
    assert TWIST_UNITS == ("m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s")


@pytest.mark.parametrize("kind", KINDS)
def test_every_twist_port_uses_the_twist_units(kind: str) -> None:
    block = KINDS[kind].block
    for port in (*block.inputs, *block.outputs):
        if port.name.startswith("twist"):
            assert port.units == TWIST_UNITS, f"{kind}.{port.name}"


def test_the_linear_models_cover_exactly_the_filter_kinds() -> None:
    assert set(linear._FILTER_SYSTEMS) == set(FILTER_KINDS)


@pytest.mark.parametrize("kind", FILTER_KINDS)
def test_every_filter_kind_has_a_linear_model(kind: str) -> None:
    system = linear.filter_system(EstimatorParams(filter=kind))
    assert (system is None) == (kind == "none")


@pytest.mark.parametrize(
    ("module", "table"), [(report, "_SETS"), (plots, "_PLOTS")], ids=["report", "plots"]
)
def test_the_report_and_the_plots_cover_exactly_the_metric_sets(module, table: str) -> None:
    assert list(getattr(module, table)) == list(METRIC_SETS)


def test_the_metric_sets_name_only_known_component_kinds() -> None:
    for name, needed in METRIC_SETS.items():
        for alternatives in needed:
            kinds = (alternatives,) if isinstance(alternatives, str) else alternatives
            assert set(kinds) <= set(KINDS), name


@pytest.mark.parametrize(
    ("file", "arm", "controller"),
    [
        ("teleecho_slide.yaml", "panda", "impedance"),
        ("teleecho_slide_ur5.yaml", "plant", "ur5_impedance"),
    ],
)
def test_a_teleecho_scenario_has_one_of_the_teleecho_kinds(
    file: str, arm: str, controller: str
) -> None:
    scenario = load_scenario(SCENARIOS / file)
    assert scenario.component_of_kinds(TELEECHO_ARMS).kind.name == arm
    assert scenario.component_of_kinds(TELEECHO_CONTROLLERS).kind.name == controller


def test_the_campaign_defines_exactly_the_kinds_the_command_line_names() -> None:
    from hoh_cosim.rehearsal.campaign import KINDS as CAMPAIGN
    from hoh_cosim.rehearsal.faults import CAMPAIGN_KINDS

    assert tuple(CAMPAIGN) == CAMPAIGN_KINDS  # the order too: it decides each seed's first fault
