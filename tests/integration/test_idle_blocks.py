"""`idle_until` (the block contract): the in-process master skips a block's idle steps, and the
run is the same as one that calls every step."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hoh_cosim.cosim import engines
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.scenario import load_scenario
from plant_models.sensors import FSE103Sensor, FT150Sensor

ROOT = Path(__file__).resolve().parents[2]


def test_a_sensor_between_packets_idles_until_its_next_packet():
    sensor = FT150Sensor()
    inputs = {"wrench_S_true": np.arange(6.0)}
    held = sensor.step(0.0, 1e-3, inputs)
    state = sensor.rng.bit_generator.state
    t, stepped = 1e-3, 0
    while t + 1e-3 < sensor.idle_until:
        assert sensor.step(t, 1e-3, inputs) is held  # the same outputs, nothing drawn
        t, stepped = t + 1e-3, stepped + 1
    assert stepped >= 3  # the first packet sampled at 5 ms, on 1 ms steps
    assert sensor.rng.bit_generator.state == state
    sensor.step(t, 1e-3, inputs)  # the next step samples the packet: its noise is drawn
    assert sensor.rng.bit_generator.state != state
    probe = FSE103Sensor()
    assert probe.idle_until > 0.0


def test_a_run_that_skips_idle_steps_equals_one_that_calls_them(monkeypatch):
    scenario = load_scenario(ROOT / "scenarios" / "contact_scan.yaml", duration_s=4.0)
    skipping = simulate(scenario, "inprocess", progress=False)
    inline = engines._inline
    skipped = []

    def never_idle(rt):
        *parts, idles = inline(rt)
        skipped.append(idles is not None)
        return (*parts, None)

    monkeypatch.setattr(engines, "_inline", never_idle)
    calling = simulate(scenario, "inprocess", progress=False)
    assert sum(skipped) >= 2  # both sensors would idle
    assert calling.columns == skipping.columns
    np.testing.assert_array_equal(calling.values, skipping.values)
