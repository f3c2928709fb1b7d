"""A failing FMU call, as the user meets it: one `RunError` line naming the component, the FMU, the
call, the time and the FMU's own last message (`hoh_cosim.cosim.engines.FmuRuntime`).

The FMU is test_fmus.py's: a block that echoes its input and raises once t > `fail_after_s`. Its
adapter logs the exception as an FMI error and `fmi2DoStep` returns fmi2Discard, which fmpy's
public call turns into an `FMICallException` and the master into the `RunError` checked here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.scenario import ComponentSpec, Scenario
from hoh_cosim.errors import RunError
from hoh_cosim.kinds import ComponentKind
from tests.integration.test_fmus import _BOOM_MODULE, _build_boom_fmu


def test_a_failing_step_is_one_run_error_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fmu, module = _build_boom_fmu(tmp_path, monkeypatch)
    kind = ComponentKind("boom", module.BoomBlock, module.BoomParams, _BOOM_MODULE, "raises")
    component = ComponentSpec(
        "boomer", kind, 1, module.BoomParams(fail_after_s=0.0205), seed=0, fmu=fmu
    )
    scenario = Scenario(
        path=tmp_path / "boom.yaml",
        name="boom",
        description="a component that raises",
        duration_s=0.05,
        dt_s=0.001,
        seed=0,
        metrics="none",
        components={"boomer": component},
        connections=(),
        input_defaults={("boomer", "u"): np.array([0.5])},
        events=(),
        record=("boomer.y",),
    )
    with pytest.raises(RunError) as caught:
        simulate(scenario, "fmu", fmu_paths={}, progress=False)
    message = str(caught.value)
    assert "\n" not in message
    # the first step past 0.0205 s starts at t = 0.021 s
    assert message == (
        "boomer (HohBoom): fmi2DoStep at t = 0.021 s returned Discard: "
        "fmi2DoStep at t = 0.021 s: ValueError: boom at t = 0.021 s"
    ), message
    assert caught.value.__cause__ is None  # raised `from None`: no fmpy traceback behind it
