"""Parameter trees: leaves (names, kinds, units, tunability), with_values, from_mapping, override."""

from __future__ import annotations

import re
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
import pytest

from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.estimator import EstimatorParams
from hoh_cosim.control.frames import R_SP_SEED
from hoh_cosim.control.sequencer import SequencerParams
from hoh_cosim.control.supervisor import LimitParams
from hoh_cosim.errors import ConfigError
from hoh_cosim.params import Leaf, from_mapping, leaves, override, with_values
from plant_models.sensors import FT150Params, HousingParams


def by_name(params: object) -> dict[str, Leaf]:
    return {leaf.name: leaf for leaf in leaves(params)}


def values_of(params: object) -> dict[str, Any]:
    return {leaf.name: leaf.value for leaf in leaves(params)}


def changed_leaves(before: object, after: object) -> dict[str, Any]:
    old, new = values_of(before), values_of(after)
    assert old.keys() == new.keys()
    return {name: new[name] for name in old if new[name] != old[name]}


# --- leaves: names and kinds ------------------------------------------------------------------


def test_leaf_names_use_dots_for_nesting_and_number_vector_elements_from_one():
    params = EstimatorParams()
    names = [leaf.name for leaf in leaves(params)]
    assert len(names) == len(set(names))
    # field order, nested fields flattened in place
    assert names[:4] == ["tool.mass_kg", "tool.p_SC_S[1]", "tool.p_SC_S[2]", "tool.p_SC_S[3]"]
    assert names.index("probe_bias[3]") + 1 == names.index("filter")
    assert not any(re.search(r"\[0\]", n) for n in names)
    assert [n for n in names if n.startswith("ft_bias")] == [f"ft_bias[{i}]" for i in range(1, 7)]
    assert {f"hand_torque_kalman.{v}[{i}]" for v in "qr" for i in (1, 2, 3)} <= set(names)
    assert "butterworth.order" in names
    assert "one_euro_torque.beta" in names


def test_a_matrix_flattens_row_by_row_into_nine_leaves():
    leaf = by_name(EstimatorParams())
    values = [leaf[f"R_SP[{i}]"].value for i in range(1, 10)]
    np.testing.assert_array_equal(values, np.asarray(R_SP_SEED).reshape(9))
    assert "R_SP[10]" not in leaf


def test_leaf_values_follow_the_parameters():
    params = EstimatorParams(probe_mass_kg=0.125, ft_bias=[1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    leaf = by_name(params)
    assert leaf["probe_mass_kg"].value == 0.125
    assert [leaf[f"ft_bias[{i}]"].value for i in range(1, 7)] == [1.0, 2.0, 3.0, 0.1, 0.2, 0.3]
    assert leaf["g_B[3]"].value == pytest.approx(-9.81)
    assert leaf["tool.mass_kg"].value == params.tool.mass_kg


def test_leaf_kinds():
    leaf = by_name(EstimatorParams())
    assert leaf["use_probe"].kind == "boolean"
    assert leaf["use_probe"].value is True
    assert leaf["ft_rebias_packets"].kind == "integer"
    assert type(leaf["ft_rebias_packets"].value) is int
    assert leaf["ft_rebias_packets"].value == 500
    assert leaf["butterworth.order"].kind == "integer"
    assert leaf["filter"].kind == "string"
    assert leaf["filter"].value == "kalman"
    assert leaf["probe_mass_kg"].kind == "real"
    for name, lf in leaf.items():
        if "[" in name:  # every vector element is a real
            assert lf.kind == "real", name
            assert type(lf.value) is float, name
    seq = by_name(SequencerParams())
    assert seq["directions"].kind == "integer"
    housing = by_name(HousingParams())
    assert [housing[f"play_N[{i}]"].kind for i in (1, 2)] == ["real"] * 2


# --- leaves: units ----------------------------------------------------------------------------


def test_units_come_from_the_class_and_per_element_tuples():
    leaf = by_name(EstimatorParams())
    assert leaf["probe_mass_kg"].unit == "kg"
    assert leaf["tool.mass_kg"].unit == "kg"  # the nested class's own UNITS
    assert leaf["tool.p_SC_S[2]"].unit == "m"
    assert [leaf[f"ft_bias[{i}]"].unit for i in range(1, 7)] == ["N"] * 3 + ["N.m"] * 3
    assert [leaf[f"hand_force_kalman.p0[{i}]"].unit for i in (1, 2, 3)] == [
        "N2",
        "N2/s2",
        "N2/s4",
    ]
    assert leaf["ft_rebias_packets"].unit == "1"
    assert leaf["butterworth.order"].unit == "1"
    # booleans and strings carry no unit
    assert leaf["use_probe"].unit is None
    assert leaf["filter"].unit is None
    ft = by_name(FT150Params())
    assert [ft[f"drift_per_sqrt_s[{i}]"].unit for i in range(1, 7)] == ["N/s0.5"] * 3 + [
        "N.m/s0.5"
    ] * 3


def test_a_parent_sets_the_unit_of_a_nested_field_by_its_dotted_path():
    est = by_name(EstimatorParams())
    # the same KalmanParams class filters forces and torques: the estimator says which
    assert est["hand_force_kalman.q[1]"].unit == "N2/s5"
    assert est["probe_force_kalman.q[3]"].unit == "N2/s5"
    assert est["hand_torque_kalman.q[1]"].unit == "N2.m2/s5"
    assert est["hand_torque_kalman.r[2]"].unit == "N2.m2"
    assert [est[f"hand_torque_kalman.p0[{i}]"].unit for i in (1, 2, 3)] == [
        "N2.m2",
        "N2.m2/s2",
        "N2.m2/s4",
    ]
    assert est["one_euro_force.beta"].unit == "1/N"
    assert est["one_euro_torque.beta"].unit == "1/(N.m)"
    assert est["one_euro_torque.min_cutoff_hz"].unit == "Hz"  # not overridden: the child's
    ctl = by_name(ControllerParams())
    assert ctl["translation.slope[1]"].unit == "m/(s.N)"
    assert ctl["rotation.slope[1]"].unit == "rad/(s.N.m)"
    assert ctl["rotation.sigmoid_steepness[3]"].unit == "1/(N.m)"
    assert ctl["translation.sigmoid_steepness[3]"].unit == "1/N"
    assert ctl["rotation.law"].unit is None


@dataclass(frozen=True)
class _Inner:
    UNITS: ClassVar[dict[str, Any]] = {"x": "inner", "y": "inner", "z": "inner"}
    x: float = 1.0
    y: float = 2.0
    z: float = 3.0


@dataclass(frozen=True)
class _Middle:
    UNITS: ClassVar[dict[str, Any]] = {"inner.x": "middle", "inner.y": "middle"}
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"inner"})
    inner: _Inner = field(default_factory=_Inner)
    w: float = 0.0


@dataclass(frozen=True)
class _Outer:
    UNITS: ClassVar[dict[str, Any]] = {"middle.inner.x": "outer", "flag": "1", "label": "m"}
    TUNABLE: ClassVar[frozenset[str]] = frozenset({"flag"})
    middle: _Middle = field(default_factory=_Middle)
    deep: _Middle = field(default_factory=_Middle)
    flag: bool = False
    label: str = "a"


def test_the_outermost_class_naming_a_field_sets_its_unit():
    leaf = by_name(_Outer())
    assert leaf["middle.inner.x"].unit == "outer"
    assert leaf["middle.inner.y"].unit == "middle"
    assert leaf["middle.inner.z"].unit == "inner"
    # the outer override names `middle`, not `deep`: deep keeps the middle's and inner's units
    assert leaf["deep.inner.x"].unit == "middle"
    assert leaf["middle.w"].unit is None
    # a boolean or a string has no unit, whatever UNITS says
    assert leaf["flag"].unit is None
    assert leaf["label"].unit is None


def test_tunability_is_inherited_by_everything_inside_a_tunable_field():
    tunable = {leaf.name for leaf in leaves(_Outer()) if leaf.tunable}
    assert tunable == {
        "middle.inner.x",
        "middle.inner.y",
        "middle.inner.z",
        "deep.inner.x",
        "deep.inner.y",
        "deep.inner.z",
        "flag",
    }


# --- leaves: tunable --------------------------------------------------------------------------


def test_ft150_tunable_leaves_are_the_declared_fields():
    leaf = by_name(FT150Params())
    tunable = {name for name, lf in leaf.items() if lf.tunable}
    expected = {"connected"} | {
        f"{base}[{i}]"
        for base in ("offset", "noise_sigma", "drift_per_sqrt_s")
        for i in range(1, 7)
    }
    assert tunable == expected
    assert not leaf["rate_hz"].tunable
    assert not leaf["quantisation[1]"].tunable
    assert not leaf["ideal"].tunable


def test_controller_tunable_subtrees_are_tunable_throughout():
    leaf = by_name(ControllerParams())
    for name, lf in leaf.items():
        if name.split(".")[0] in ("translation", "rotation", "limits"):
            assert lf.tunable, name  # LimitParams/AdmittanceGains declare no TUNABLE themselves
    assert leaf["limits.workspace_min_B[2]"].tunable
    assert leaf["fixture_up_B[3]"].tunable
    assert leaf["contact_compensation"].tunable
    assert not leaf["use_probe"].tunable
    assert not leaf["ft_period_s"].tunable
    assert not leaf["probe_period_s"].tunable


def test_a_class_without_tunable_has_no_tunable_leaves():
    assert not any(leaf.tunable for leaf in leaves(EstimatorParams()))
    assert not any(leaf.tunable for leaf in leaves(SequencerParams()))


def test_a_field_that_is_not_a_parameter_is_refused():
    @dataclass(frozen=True)
    class Bad:
        names: list = field(default_factory=list)

    with pytest.raises(ConfigError, match=r"^names: cannot express a list as a parameter"):
        leaves(Bad())


# --- with_values ------------------------------------------------------------------------------


def _another(leaf: Leaf) -> Any:
    if leaf.kind == "boolean":
        return not leaf.value
    if leaf.kind == "integer":
        return leaf.value + 1
    return leaf.value * 1.5 + 0.25


@pytest.mark.parametrize(
    "params", [FT150Params(), SequencerParams()], ids=lambda p: type(p).__name__
)
def test_setting_one_leaf_changes_exactly_that_leaf(params):
    before = values_of(params)
    for leaf in leaves(params):
        value = _another(leaf)
        new = with_values(params, {leaf.name: value})
        assert type(new) is type(params)
        assert changed_leaves(params, new) == {leaf.name: value}, leaf.name
    assert values_of(params) == before  # the original is untouched


def test_with_values_sets_nested_and_indexed_leaves_together():
    ctl = ControllerParams()
    new = with_values(
        ctl,
        {
            "translation.slope[2]": 0.02,
            "limits.max_linear_speed": 0.2,
            "rotation.law": "sigmoid",
            "virtual_fixture": True,
        },
    )
    np.testing.assert_array_equal(new.translation.slope, [0.0125, 0.02, 0.0125])
    assert new.limits.max_linear_speed == 0.2
    assert new.rotation.law == "sigmoid"
    assert new.virtual_fixture is True
    assert set(changed_leaves(ctl, new)) == {
        "translation.slope[2]",
        "limits.max_linear_speed",
        "rotation.law",
        "virtual_fixture",
    }
    # the original stays as it was
    np.testing.assert_array_equal(ctl.translation.slope, [0.0125] * 3)
    assert ctl.limits.max_linear_speed == 0.1
    assert ctl.virtual_fixture is False


def test_with_values_runs_the_dataclass_validation():
    # fixture_up_B is normalised by ControllerParams: the result went through __post_init__
    new = with_values(ControllerParams(), {"fixture_up_B[1]": 1.0})
    np.testing.assert_allclose(new.fixture_up_B, np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0))
    assert not new.fixture_up_B.flags.writeable
    ft = with_values(FT150Params(), {"offset[4]": 0.5})
    assert not ft.offset.flags.writeable
    assert ft.offset[3] == 0.5


def test_with_values_keeps_a_tuple_a_tuple_and_a_matrix_a_matrix():
    housing = with_values(HousingParams(), {"play_N[2]": 0.5})
    assert housing.play_N == (0.2, 0.5)
    assert isinstance(housing.play_N, tuple)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    est = with_values(EstimatorParams(), {f"R_SP[{i + 1}]": x for i, x in enumerate(R.reshape(9))})
    assert est.R_SP.shape == (3, 3)
    np.testing.assert_array_equal(est.R_SP, R)


def test_with_values_sets_matrix_elements_in_row_order():
    R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # not symmetric
    est = EstimatorParams(R_SP=R)
    # flip the signs of R[0, 2] and R[1, 1]: still a rotation
    new = with_values(est, {"R_SP[3]": -1.0, "R_SP[5]": -1.0})
    np.testing.assert_array_equal(new.R_SP, [[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(est.R_SP, R)


def test_with_values_converts_numbers_to_the_leaf_kind():
    est = with_values(
        EstimatorParams(),
        {
            "probe_mass_kg": 2,  # an integer for a real
            "ft_rebias_packets": np.int64(7),
            "use_probe": np.bool_(False),
            "g_B[3]": np.float32(-9.75),
        },
    )
    assert type(est.probe_mass_kg) is float
    assert est.probe_mass_kg == 2.0
    assert type(est.ft_rebias_packets) is int
    assert est.ft_rebias_packets == 7
    assert est.use_probe is False
    assert est.g_B[2] == pytest.approx(-9.75)


@pytest.mark.parametrize(
    "name",
    [
        "translation.bogus",
        "bogus",
        "translation.slope[4]",
        "translation.slope[0]",
        "translation.slope",  # a whole vector is not a leaf
        "translation",  # nor is a subtree
        "limits.max_linear_speed[1]",
    ],
)
def test_with_values_refuses_an_unknown_leaf_and_names_it(name):
    with pytest.raises(
        ConfigError, match=rf"^{re.escape(name)}: unknown parameter of ControllerParams"
    ):
        with_values(ControllerParams(), {name: 1.0})


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        ("probe_mass_kg", "1.5", "expected a number, got '1.5'"),
        ("probe_mass_kg", True, "expected a number, got True"),
        ("probe_mass_kg", None, "expected a number, got None"),
        ("g_B[3]", "down", "expected a number, got 'down'"),
        ("use_probe", 1, "expected true or false, got 1"),
        ("use_probe", "true", "expected true or false, got 'true'"),
        ("ft_rebias_packets", True, "expected an integer, got True"),
        ("ft_rebias_packets", 5.0, "expected an integer, got 5.0"),
        ("ft_rebias_packets", "5", "expected an integer, got '5'"),
        ("filter", 3, "expected a string, got 3"),
    ],
)
def test_with_values_refuses_the_wrong_type(name, value, expected):
    with pytest.raises(ConfigError, match=rf"^{re.escape(name)}: {re.escape(expected)}$"):
        with_values(EstimatorParams(), {name: value})


@pytest.mark.parametrize(
    ("params", "values", "message"),
    [
        (SequencerParams(), {"hold_s": -1.0}, r"^hold_s must be > 0"),
        (SequencerParams(), {"directions": 0}, r"^directions must be an integer >= 1, got 0"),
        (SequencerParams(), {"tilt_max_deg": 150.0}, r"^tilt_max_deg must be <= 120"),
        (HousingParams(), {"play_N[1]": 0.9}, r"^play_N: expected \(low, high\) with low <= high"),
        (EstimatorParams(), {"filter": "median"}, r"^filter: expected one of kalman"),
        (EstimatorParams(), {"R_SP[1]": 2.0}, r"^R_SP: not a rotation matrix"),
        (EstimatorParams(), {"g_B[1]": float("nan")}, r"^g_B: expected finite numbers"),
        # a nested class's error is prefixed with the path to it
        (ControllerParams(), {"limits.max_linear_speed": -0.1}, r"^limits\.max_linear_speed must"),
        (EstimatorParams(), {"tool.mass_kg": -1.0}, r"^tool\.mass_kg must be >= 0"),
        (
            ControllerParams(),
            {"translation.slope[2]": -1.0},
            r"^translation\.slope must be >= 0 on every axis",
        ),
        # a check across fields
        (
            ControllerParams(),
            {"limits.probe_force_soft_cap": 30.0},
            r"^limits\.probe_force_soft_cap \(30\.0 N\) must not exceed",
        ),
    ],
)
def test_with_values_reports_what_the_dataclass_rejects(params, values, message):
    before = values_of(params)
    with pytest.raises(ConfigError, match=message):
        with_values(params, values)
    assert values_of(params) == before


def test_every_leaf_round_trips_through_with_values():
    for params in (ControllerParams(), EstimatorParams(), FT150Params(), SequencerParams()):
        again = with_values(params, values_of(params))
        assert leaves(again) == leaves(params)
        assert type(again) is type(params)


# --- identity when nothing changes ------------------------------------------------------------


def test_unchanged_parameters_are_returned_as_the_same_object():
    ctl = ControllerParams()
    assert with_values(ctl, {}) is ctl
    assert from_mapping(ctl, {}) is ctl
    assert from_mapping(ctl, {"limits": {}, "translation": {}}, "controller") is ctl
    assert with_values(ctl, {"contact_compensation": True}) is ctl  # the value it already has


def test_untouched_subtrees_keep_their_identity():
    ctl = ControllerParams()
    new = with_values(ctl, {"translation.deadband[3]": 0.5})
    assert new is not ctl
    assert new.translation is not ctl.translation
    assert new.rotation is ctl.rotation
    assert new.limits is ctl.limits
    est = EstimatorParams()
    new_est = from_mapping(est, {"hand_torque_kalman": {"r": 0.001}})
    assert new_est.hand_force_kalman is est.hand_force_kalman
    assert new_est.tool is est.tool
    assert new_est.hand_torque_kalman is not est.hand_torque_kalman


# --- from_mapping -----------------------------------------------------------------------------


def test_from_mapping_sets_nested_values():
    ctl = ControllerParams()
    new = from_mapping(
        ctl,
        {
            "translation": {"slope": [0.01, 0.02, 0.03], "law": "sigmoid"},
            "limits": {"max_linear_speed": 0.2, "workspace_max_B": [0.5, 0.6, 0.7]},
            "virtual_fixture": True,
        },
        "controller",
    )
    np.testing.assert_array_equal(new.translation.slope, [0.01, 0.02, 0.03])
    assert new.translation.law == "sigmoid"
    assert new.limits.max_linear_speed == 0.2
    np.testing.assert_array_equal(new.limits.workspace_max_B, [0.5, 0.6, 0.7])
    assert new.virtual_fixture is True
    assert set(changed_leaves(ctl, new)) == {
        "translation.slope[1]",
        "translation.slope[2]",
        "translation.slope[3]",
        "translation.law",
        "limits.max_linear_speed",
        "limits.workspace_max_B[1]",
        "limits.workspace_max_B[2]",
        "limits.workspace_max_B[3]",
        "virtual_fixture",
    }


def test_from_mapping_broadcasts_one_number_to_a_whole_vector():
    ctl = from_mapping(ControllerParams(), {"rotation": {"deadband": 0.2, "slope": 1}})
    np.testing.assert_array_equal(ctl.rotation.deadband, [0.2, 0.2, 0.2])
    np.testing.assert_array_equal(ctl.rotation.slope, [1.0, 1.0, 1.0])
    housing = from_mapping(HousingParams(), {"play_N": 0.3})
    assert housing.play_N == (0.3, 0.3)
    ft = from_mapping(FT150Params(), {"offset": 0.0})
    np.testing.assert_array_equal(ft.offset, np.zeros(6))


@pytest.mark.parametrize(
    ("params", "mapping", "message"),
    [
        (
            ControllerParams(),
            {"translation": {"slope": [0.01, 0.02]}},
            "controller.translation.slope: expected a list of 3 numbers, got 2 values",
        ),
        (
            FT150Params(),
            {"offset": [0.0] * 7},
            "controller.offset: expected a list of 6 numbers, got 7 values",
        ),
        (
            EstimatorParams(),
            {"g_B": []},
            "controller.g_B: expected a list of 3 numbers, got 0 values",
        ),
        (
            ControllerParams(),
            {"translation": {"slope": "fast"}},
            "controller.translation.slope: expected a list of 3 numbers, got 'fast'",
        ),
        (
            ControllerParams(),
            {"translation": {"slope": True}},  # a boolean is not broadcast
            "controller.translation.slope: expected a list of 3 numbers, got True",
        ),
    ],
)
def test_from_mapping_refuses_a_vector_of_the_wrong_length(params, mapping, message):
    with pytest.raises(ConfigError, match=rf"^{re.escape(message)}$"):
        from_mapping(params, mapping, "controller")


def test_from_mapping_names_the_element_of_a_bad_vector():
    with pytest.raises(
        ConfigError, match=r"^controller\.translation\.slope\[2\]: expected a number, got 'x'$"
    ):
        from_mapping(ControllerParams(), {"translation": {"slope": [1.0, "x", 2.0]}}, "controller")


def test_from_mapping_refuses_an_unknown_key_listing_the_known_ones():
    with pytest.raises(ConfigError) as info:
        from_mapping(ControllerParams(), {"limits": {"max_speed": 1.0}}, "scenario.controller")
    message = str(info.value)
    assert message.startswith(
        "scenario.controller.limits.max_speed: unknown parameter of LimitParams (one of: "
    )
    known = re.search(r"\(one of: (.*)\)$", message).group(1).split(", ")
    assert known == [f.name for f in fields(LimitParams)]


def test_from_mapping_without_where_names_the_key_path_alone():
    with pytest.raises(
        ConfigError,
        match=r"^bogus: unknown parameter of ControllerParams \(one of: translation, rotation, ",
    ):
        from_mapping(ControllerParams(), {"bogus": 1})


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"use_probe": "yes"}, r"^est\.use_probe: expected true or false, got 'yes'$"),
        ({"ft_rebias_packets": 2.5}, r"^est\.ft_rebias_packets: expected an integer, got 2\.5$"),
        ({"probe_mass_kg": True}, r"^est\.probe_mass_kg: expected a number, got True$"),
        ({"filter": 1}, r"^est\.filter: expected a string, got 1$"),
        ({"tool": 3}, r"^est\.tool: expected a mapping of parameters, got 3$"),
        # validation errors name where and the path inside as one path
        ({"tool": {"mass_kg": -2}}, r"^est\.tool\.mass_kg: must be >= 0"),
        ({"probe_mass_kg": -1.0}, r"^est\.probe_mass_kg: must be >= 0"),
        ({"filter": "median"}, r"^est\.filter: expected one of kalman"),
    ],
)
def test_from_mapping_errors_name_where_they_came_from(mapping, message):
    with pytest.raises(ConfigError, match=message):
        from_mapping(EstimatorParams(), mapping, "est")


def test_from_mapping_converts_an_integer_for_a_real():
    est = from_mapping(EstimatorParams(), {"probe_mass_kg": 2, "ft_rebias_packets": 0})
    assert type(est.probe_mass_kg) is float
    assert est.probe_mass_kg == 2.0
    assert est.ft_rebias_packets == 0


# --- override ---------------------------------------------------------------------------------


def test_override_a_dotted_path():
    ctl = ControllerParams()
    new = override(ctl, "limits.max_linear_speed", 0.2)
    assert new.limits.max_linear_speed == 0.2
    assert changed_leaves(ctl, new) == {"limits.max_linear_speed": 0.2}
    assert override(ctl, "contact_compensation", False).contact_compensation is False
    assert override(EstimatorParams(), "filter", "butterworth").filter == "butterworth"


def test_override_one_element_of_a_vector():
    ctl = ControllerParams()
    new = override(ctl, "translation.slope[2]", 0.03)
    np.testing.assert_array_equal(new.translation.slope, [0.0125, 0.03, 0.0125])
    assert changed_leaves(ctl, new) == {"translation.slope[2]": 0.03}


def test_override_a_whole_vector_with_a_list_or_a_number():
    ctl = ControllerParams()
    new = override(ctl, "translation.deadband", [0.5, 0.6, 0.7])
    np.testing.assert_array_equal(new.translation.deadband, [0.5, 0.6, 0.7])
    new = override(ctl, "translation.deadband", 0.4)
    np.testing.assert_array_equal(new.translation.deadband, [0.4, 0.4, 0.4])
    est = override(EstimatorParams(), "hand_force_kalman.q", 5.0)
    np.testing.assert_array_equal(est.hand_force_kalman.q, [5.0, 5.0, 5.0])


@pytest.mark.parametrize(
    ("path", "message"),
    [
        (
            "translation.bogus",
            r"^--set ctl\.translation\.bogus: unknown parameter of AdmittanceGains \(one of: law, ",
        ),
        ("bogus", r"^--set ctl\.bogus: unknown parameter of ControllerParams \(one of: "),
        ("translation.slope[4]", r"^--set ctl\.translation\.slope\[4\]: unknown parameter"),
        ("bogus[1]", r"^--set ctl\.bogus\[1\]: unknown parameter of ControllerParams"),
    ],
)
def test_override_an_unknown_path(path, message):
    with pytest.raises(ConfigError, match=message):
        override(ControllerParams(), path, 1.0, "--set ctl")


def test_override_reports_bad_values_with_where():
    ctl = ControllerParams()
    with pytest.raises(ConfigError, match=r"^ctl\.translation\.slope: must be >= 0 on every axis"):
        override(ctl, "translation.slope[2]", -1.0, "ctl")
    with pytest.raises(ConfigError, match=r"^ctl\.translation\.slope\[2\]: expected a number"):
        override(ctl, "translation.slope[2]", "fast", "ctl")
    with pytest.raises(ConfigError, match=r"^ctl\.translation: expected a mapping of parameters"):
        override(ctl, "translation", 1.0, "ctl")
    with pytest.raises(ConfigError, match=r"^ctl\.limits\.max_linear_speed: must be > 0"):
        override(ctl, "limits.max_linear_speed", 0.0, "ctl")
    with pytest.raises(ConfigError, match=r"^ctl\.virtual_fixture: expected true or false"):
        override(ctl, "virtual_fixture", "on", "ctl")
