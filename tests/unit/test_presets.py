"""Presets (hoh_cosim.presets): the shipped ones, a user's own file, where they apply (a scenario,
a rig file, the command line) in which order, and the one-line errors for what is wrong.

Every user file is written to tmp_path; the expected values are spelled out here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cli import main
from hoh_cosim.control.admittance import ROTATION_GAINS, TRANSLATION_GAINS
from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.estimator import (
    FSE103_NOISE_MAX,
    FT150_NOISE_MAX_S,
    FT150_TORQUE_NOISE_MAX_S,
    EstimatorParams,
    default_kalman,
)
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.config import load_config
from hoh_cosim.params import leaves
from hoh_cosim.presets import DEFAULT_PRESET, PRESETS_DIR, load_preset, preset_names

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
SHIPPED = ("seed", "transparent", "checked", "hold", "follow", "glide", "clinical")


def test_the_shipped_presets_load_in_their_order_with_one_line_each():
    assert preset_names() == list(SHIPPED)
    for name in SHIPPED:
        preset = load_preset(name)
        assert preset.name == name
        assert preset.path == PRESETS_DIR / f"{name}.yaml"
        assert preset.description
        assert "\n" not in preset.description
        assert preset.label == name


def test_the_seed_preset_pins_the_seeds_numbers():
    """The seed's law, written out: today it equals the blocks' defaults, so every scenario that
    pins it gives what the blocks' defaults gave."""
    seed = load_preset("seed")
    assert seed.changes() == {}
    assert seed.probe_check_s == 0.0
    assert seed.estimator.filter == "kalman"
    for name, noise in (
        ("hand_force_kalman", FT150_NOISE_MAX_S),
        ("hand_torque_kalman", FT150_TORQUE_NOISE_MAX_S),
        ("probe_force_kalman", FSE103_NOISE_MAX),
    ):
        kalman, expected = getattr(seed.estimator, name), default_kalman(noise)
        for field in ("q", "r", "p0"):
            np.testing.assert_array_equal(getattr(kalman, field), getattr(expected, field))
    for gains, expected in (
        (seed.controller.translation, TRANSLATION_GAINS),
        (seed.controller.rotation, ROTATION_GAINS),
    ):
        assert gains.law == expected.law
        np.testing.assert_array_equal(gains.slope, expected.slope)
        np.testing.assert_array_equal(gains.deadband, expected.deadband)
    np.testing.assert_array_equal(seed.controller.translation.deadband, [0.95, 0.95, 0.25])
    np.testing.assert_array_equal(seed.controller.translation.slope, [0.0125] * 3)


def test_the_clinical_preset_has_every_piece_and_the_probe_check():
    clinical = load_preset("clinical")
    c, e = clinical.controller, clinical.estimator
    assert clinical.probe_check_s == 20.0
    assert (e.probe_correction.kind, e.probe_correction.check_s) == ("online", 20.0)
    assert e.probe_correction.across_from_wrist_s == 5.0
    assert c.glide.enabled
    assert c.follow.enabled
    assert c.release.enabled
    assert c.hold.enabled
    assert c.recovery.enabled
    assert (c.hold.motion, c.hold.retake_band_N, c.hold.swing_s) == ("normal", 1.0, 0.1)
    # the rest is the seed's law
    assert c.translation.law == "deadband_linear"
    assert e.filter == "kalman"
    assert not c.virtual_fixture
    assert not c.passivity.enabled


def test_a_preset_sets_only_what_it_names():
    transparent = load_preset("transparent")
    assert transparent.changes() == {
        "estimator.filter": "lead_lowpass",
        "controller.translation.law": "variable",
        "controller.release.enabled": True,
        "controller.passivity.enabled": True,
    }


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_a_users_preset_file_extends_a_shipped_one(tmp_path):
    mine = write(
        tmp_path / "mine.yaml",
        "description: clinical with a lighter deadband\n"
        "extends: clinical\n"
        "controller: {translation: {deadband: [0.8, 0.8, 0.25]}}\n",
    )
    preset = load_preset(mine)
    assert preset.name == "mine"
    assert preset.label == str(mine)
    assert not preset.shipped
    np.testing.assert_array_equal(preset.controller.translation.deadband, [0.8, 0.8, 0.25])
    assert preset.controller.hold.enabled
    assert preset.probe_check_s == 20.0


def test_a_preset_file_extends_another_file_by_its_path(tmp_path):
    write(tmp_path / "base.yaml", "description: base\ncontroller: {release: {enabled: true}}\n")
    sub = tmp_path / "sub"
    sub.mkdir()
    mine = write(
        sub / "mine.yaml",
        "description: on the base\nextends: ../base.yaml\nsession: {probe_check_s: 5.0}\n",
    )
    preset = load_preset(mine)
    assert preset.controller.release.enabled
    assert preset.probe_check_s == 5.0
    assert preset.estimator.probe_correction.kind == "online"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("description: x\nsettings: {}\n", r"mine.yaml: settings: unknown key \(expected one of: "),
        (
            "description: x\ncontroller: {hold: {enabled: yes please}}\n",
            r"mine.yaml: controller.hold.enabled: expected true or false, got 'yes please'",
        ),
        (
            "description: x\ncontroller: {glide: {corner_hz: -1.0}}\n",
            r"mine.yaml: controller.glide.corner_hz: ",
        ),
        (
            "description: x\ncontroller: {nope: 1}\n",
            r"mine.yaml: controller.nope: unknown parameter of ControllerParams",
        ),
        (
            "description: x\nestimator: {filter: median}\n",
            r"mine.yaml: estimator.filter: expected one of .*got 'median'",
        ),
        ("description: x\nsession: {probe_check_s: -2}\n", r"session.probe_check_s: expected a"),
        ("description: x\nsession: {warm_up_s: 2}\n", r"session.warm_up_s: unknown key"),
        ("controller: {}\n", r"mine.yaml: description: expected one line of text"),
        ("description: x\nextends: nope\n", r"extends: unknown preset 'nope' \(presets: seed, "),
        ("description: x\nextends: mine.yaml\n", r"extends: 'mine.yaml' extends this file again"),
        ("description: x\ncontroller: [1, 2]\n", r"mine.yaml: controller: expected a mapping"),
    ],
)
def test_a_bad_preset_file_is_one_line_naming_the_file_and_the_key(tmp_path, text, message):
    mine = write(tmp_path / "mine.yaml", text)
    with pytest.raises(ConfigError, match=message) as info:
        load_preset(mine)
    assert "\n" not in str(info.value)


def test_an_unknown_preset_lists_the_known_ones():
    with pytest.raises(ConfigError) as info:
        load_preset("turbo")
    assert str(info.value) == (
        "preset 'turbo': unknown (presets: seed, transparent, checked, hold, follow, glide, "
        "clinical; or the path of a preset file)"
    )
    with pytest.raises(ConfigError, match=r"preset 'no/such.yaml': no such preset file"):
        load_preset("no/such.yaml")


# --- in a scenario --------------------------------------------------------------------------------


def test_a_scenario_without_a_preset_takes_the_default_and_its_own_params_win():
    scenario = load_scenario(SCENARIOS / "clinical_assisted.yaml")
    assert scenario.preset is not None
    assert scenario.preset.name == DEFAULT_PRESET
    # the file's own estimator params (the rig's tool) are over the preset, and reported
    changes = scenario.preset_changes()
    assert changes["estimator.tool.mass_kg"] == 0.48
    assert changes["estimator.probe_rebias_packets"] == 100


def test_the_preset_comes_before_the_files_params_and_set_after_both(tmp_path):
    text = (SCENARIOS / "contact_scan_fixture.yaml").read_text(encoding="utf-8")
    scenario = load_scenario(SCENARIOS / "contact_scan_fixture.yaml", preset="transparent")
    controller = scenario.components["controller"].params
    assert controller.virtual_fixture  # the file's own
    assert controller.passivity.enabled
    assert controller.translation.law == "variable"
    scenario = load_scenario(
        SCENARIOS / "contact_scan_fixture.yaml",
        ["controller.passivity.enabled=false", "controller.virtual_fixture=false"],
        preset="transparent",
    )
    controller = scenario.components["controller"].params
    assert not controller.passivity.enabled
    assert not controller.virtual_fixture
    assert scenario.preset_changes()["controller.passivity.enabled"] is False
    assert "virtual_fixture: true" in text


def test_the_files_preset_key_and_the_option(tmp_path):
    base = (SCENARIOS / "release.yaml").read_text(encoding="utf-8")
    mine = write(
        tmp_path / "release.yaml",
        base.replace("extends: circles.yaml", f"extends: {SCENARIOS / 'circles.yaml'}")
        + "preset: transparent\n",
    )
    assert load_scenario(mine).preset.name == "transparent"
    assert load_scenario(mine, preset="seed").preset.name == "seed"
    write(tmp_path / "bad.yaml", base.replace("extends: circles.yaml", "") + "preset: 7\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: preset: expected a preset's name"):
        load_scenario(tmp_path / "bad.yaml")


def test_a_probe_check_comes_before_the_hands_task_and_lengthens_the_run():
    plain = load_scenario(SCENARIOS / "clinical_assisted.yaml", preset="seed")
    checked = load_scenario(SCENARIOS / "clinical_assisted.yaml", preset="checked")
    op0, op1 = plain.components["operator"].params, checked.components["operator"].params
    assert (op0.probe_check_s, op1.probe_check_s) == (0.0, 20.0)
    assert op1.start_s == op0.start_s + 20.0
    assert checked.duration_s == plain.duration_s + 20.0
    estimator = checked.components["estimator"].params
    assert (estimator.probe_correction.kind, estimator.probe_correction.check_s) == ("online", 20.0)
    # --duration is the run's length, whatever the preset
    assert (
        load_scenario(SCENARIOS / "clinical_assisted.yaml", (), 5.0, None, "checked").duration_s
        == 5.0
    )
    # a scenario whose hand checks the probe itself keeps its own check
    own = load_scenario(SCENARIOS / "contact_scan_online.yaml", preset="checked")
    mine = load_scenario(SCENARIOS / "contact_scan_online.yaml", preset="seed")
    assert leaves(own.components["operator"].params) == leaves(mine.components["operator"].params)
    assert own.duration_s == mine.duration_s


def test_a_scenario_without_an_estimator_or_a_controller_has_no_preset():
    scenario = load_scenario(SCENARIOS / "clinical_freehand.yaml", preset="clinical")
    assert scenario.preset is None
    assert scenario.preset_changes() == {}


def test_a_run_records_its_preset_and_what_differs_from_it(tmp_path, capsys):
    out = tmp_path / "run"
    status = main(
        [
            str(SCENARIOS / "release.yaml"),
            "--engine",
            "inprocess",
            "--duration",
            "0.5",
            "--preset",
            "transparent",
            "--set",
            "controller.passivity.enabled=false",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert status == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["preset"] == "transparent"
    # the option's change, and the file's own (circles.yaml's tool)
    assert summary["preset_changes"] == {
        "controller.passivity.enabled": False,
        "estimator.tool.mass_kg": 0.48,
        "estimator.tool.p_SC_S[3]": -0.075,
        "estimator.probe_rebias_packets": 100,
    }


def test_an_unknown_preset_on_the_command_line_runs_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    status = main([str(SCENARIOS / "release.yaml"), "--preset", "turbo", "--out", str(out)])
    assert status == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hoh-cosim: preset 'turbo': unknown (presets: seed, ")
    assert "\n" not in err
    assert not out.exists()


def test_an_unknown_preset_in_a_scenario_file_names_the_file(tmp_path, capsys):
    scenario = tmp_path / "mine.yaml"
    scenario.write_text(f"extends: {SCENARIOS / 'release.yaml'}\npreset: turbo\n")
    out = tmp_path / "run"
    assert main([str(scenario), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"hoh-cosim: {scenario}: preset 'turbo': unknown (presets: seed, ")
    assert "\n" not in err
    assert not out.exists()


# --- the command ----------------------------------------------------------------------------------


def test_the_presets_command_lists_every_preset(capsys):
    assert main(["presets"]) == 0
    text = capsys.readouterr().out
    for name in SHIPPED:
        assert any(line.startswith(f"{name} ") for line in text.splitlines()), name
    assert main(["presets", "clinical", "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["name"] == "clinical"
    assert shown["probe_check_s"] == 20.0
    assert shown["changes"]["controller.recovery.enabled"] is True


def test_the_presets_command_refuses_an_unknown_one_in_one_line(capsys):
    assert main(["presets", "turbo"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "unknown (presets: seed," in err


# --- on a rig -------------------------------------------------------------------------------------


def rig(tmp_path: Path, extra: str = "") -> Path:
    return write(
        tmp_path / "rig.yaml",
        "robot: {host: 192.168.1.10}\nprobe: {device: /dev/ttyACM0}\n" + extra,
    )


def test_a_rig_file_takes_a_preset_under_its_sections_and_the_option_over_it(tmp_path):
    config = load_config(rig(tmp_path))
    assert config.preset.name == DEFAULT_PRESET
    config = load_config(rig(tmp_path, "preset: hold\ncontroller: {hold: {swing_s: 0.2}}\n"))
    assert config.preset.name == "hold"
    assert config.controller.hold.enabled
    assert config.controller.hold.swing_s == 0.2
    assert config.preset_changes() == {"controller.hold.swing_s": 0.2}
    config = load_config(
        rig(tmp_path, "preset: hold\n"), ["controller.release.hold_s=0.3"], preset="clinical"
    )
    assert config.preset.name == "clinical"
    assert config.controller.recovery.enabled
    assert config.preset_changes() == {"controller.release.hold_s": 0.3}
    mine = write(tmp_path / "mine.yaml", "description: m\ncontroller: {follow: {enabled: true}}\n")
    config = load_config(rig(tmp_path, "preset: mine.yaml\n"))
    assert config.controller.follow.enabled
    assert config.preset.path == mine


def test_a_rig_files_bad_preset_is_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"rig.yaml: preset: expected a preset's name"):
        load_config(rig(tmp_path, "preset: [clinical]\n"))
    with pytest.raises(ConfigError, match=r"^/.*rig.yaml: preset 'turbo': unknown"):
        load_config(rig(tmp_path, "preset: turbo\n"))
    with pytest.raises(ConfigError, match=r"^preset 'turbo': unknown"):  # the option's: no file
        load_config(rig(tmp_path), preset="turbo")


def test_the_blocks_defaults_are_untouched_by_the_presets():
    assert leaves(EstimatorParams()) == leaves(load_preset("seed").estimator)
    assert not ControllerParams().hold.enabled
