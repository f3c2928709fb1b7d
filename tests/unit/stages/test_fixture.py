"""The virtual fixture's stage: `horizontal_fixture` along the fixed up direction or along the
probe force's direction, status FIXTURE while engaged; no state."""

from __future__ import annotations

import numpy as np
import pytest

from hoh_cosim.control.admittance import horizontal_fixture
from hoh_cosim.control.guidance.stages import fixture as fixture_module
from hoh_cosim.control.guidance.stages.fixture import Fixture
from hoh_cosim.control.supervisor import Status
from tests.unit.stages.ticks import assert_reads_only, make_command, make_tick

UP = np.array([0.0, 0.0, 1.0])
FIXTURE = int(Status.FIXTURE)


@pytest.mark.parametrize("normal", ["fixed", "contact"])
def test_the_command_is_horizontal_fixtures(normal, rng):
    stage = Fixture(1.0, UP, normal)
    engaged = 0
    for _ in range(200):
        F_probe = rng.normal(0.0, 2.0, 3)
        v = rng.normal(0.0, 0.05, 3)
        out = stage.step(make_tick(F_probe_B=F_probe), make_command(v, status=1))
        up = F_probe / np.linalg.norm(F_probe) if normal == "contact" else UP
        want, on = horizontal_fixture(v, F_probe, 1.0, up)
        np.testing.assert_allclose(out.v, want, rtol=1e-12, atol=1e-15)
        assert out.status == (1 | FIXTURE if on else 1)
        assert float(out.v @ up) <= 1e-15 or not on  # nothing out of the surface while engaged
        engaged += on
    assert 50 < engaged < 200


def test_along_the_contact_normal_only_the_motion_out_of_the_surface_goes():
    # a surface tilted 30° about y: its normal n; the command leaves it and slides along it
    n = np.array([np.sin(np.pi / 6), 0.0, np.cos(np.pi / 6)])
    along = np.array([np.cos(np.pi / 6), 0.0, -np.sin(np.pi / 6)])
    v = 0.02 * n + 0.01 * along + [0.0, 0.01, 0.0]
    out = Fixture(1.0, UP, "contact").step(make_tick(F_probe_B=5.0 * n), make_command(v))
    np.testing.assert_allclose(out.v, 0.01 * along + [0.0, 0.01, 0.0], atol=1e-15)
    fixed = Fixture(1.0, UP, "fixed").step(make_tick(F_probe_B=5.0 * n), make_command(v))
    assert fixed.v[2] == 0.0  # the fixed fixture takes out the vertical part instead
    assert fixed.v[0] == pytest.approx(v[0])


def test_under_the_threshold_and_into_the_surface_it_is_free():
    stage = Fixture(1.0, UP, "contact")
    light = stage.step(make_tick(F_probe_B=[0.0, 0.0, 0.9]), make_command([0.0, 0.0, 0.02]))
    np.testing.assert_array_equal(light.v, [0.0, 0.0, 0.02])
    assert light.status == 0
    down = stage.step(make_tick(F_probe_B=[0.0, 0.0, 5.0]), make_command([0.01, 0.0, -0.02]))
    np.testing.assert_array_equal(down.v, [0.01, 0.0, -0.02])
    assert down.status == FIXTURE  # engaged, though nothing to take out


def test_reset_forgets_nothing_because_there_is_no_state(rng):
    ticks = [make_tick(F_probe_B=rng.normal(0.0, 3.0, 3)) for _ in range(5)]
    v = rng.normal(0.0, 0.05, 3)
    stage = Fixture(1.0, UP, "contact")
    for tick in ticks[:-1]:
        stage.step(tick, make_command(v))
    stage.reset()
    again = stage.step(ticks[-1], make_command(v))
    once = Fixture(1.0, UP, "contact").step(ticks[-1], make_command(v))
    np.testing.assert_array_equal(again.v, once.v)
    assert again.status == once.status


def test_it_reads_only_the_tick_and_the_command():
    tick = make_tick(F_probe_B=[0.0, 0.0, 5.0])
    assert_reads_only(fixture_module, Fixture(1.0, UP, "contact"), tick, make_command([0, 0, 0.1]))
