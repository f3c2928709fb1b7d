"""A scenario run in the view: live as our master steps it, or after the run, and a kept run's
signals as a recording.

`CosimView` is the run's `RunWatch` (`hoh_cosim.cosim.run`): built from the loaded scenario before
anything runs, it copies the master's row of outputs every `RUN_RATE_HZ`-th of a second of
simulation time and sends them in blocks (live: a quarter of a second each, so the viewer follows;
only recorded: larger ones); an external engine (libcosim, ecos) steps on its own, so its run is
shown from the recording once it has ended. What is shown comes from `track.cosim_roles`: a scenario
without an arm's pose shows nothing in 3D.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.view import RUN_RATE_HZ
from hoh_cosim.view.scene import Scene
from hoh_cosim.view.stream import ViewStream
from hoh_cosim.view.track import cosim_roles, signals_track

__all__ = ["CosimView", "record_signals", "scene_of", "view_signals"]

TIMELINE = "sim_time"


def scene_of(scenario: Any) -> Scene:
    """The scene a scenario's components describe: the controller's limits and fixture, the
    arm's tool and phantom; the UR5's links where its arm is the UR5 plant."""
    plant = scenario.component_of_kinds(("plant", "panda", "freehand"))
    controller = scenario.component_of_kind("controller")
    params = getattr(plant, "params", None)
    ur5 = plant is not None and plant.kind.name == "plant"
    note = ""
    if plant is not None and not ur5:
        arm = "a Panda" if plant.kind.name == "panda" else "the hand alone (no robot)"
        note = f"the probe is held by {arm}: its links are not drawn"
    return Scene.of(
        getattr(controller, "params", None),
        getattr(params, "tool", None),
        getattr(params, "phantom", None),
        ur5=ur5,
        note=note,
    )


def view_signals(scenario: Any) -> tuple[str, ...]:
    """The "component.port" signals a run's view is made of."""
    return tuple(_roles(scenario).values())


def _roles(scenario: Any) -> dict[str, str]:
    return cosim_roles({name: c.kind.name for name, c in scenario.components.items()})


class CosimView:
    """A run in the view (the `RunWatch` of `run_scenario`)."""

    def __init__(
        self,
        scenario: Any,
        *,
        web_port: int | None = None,
        record: str | Path | None = None,
        rate_hz: float = RUN_RATE_HZ,
    ) -> None:
        from hoh_cosim.cosim.recording import recording_layout

        self.scenario = scenario
        self.roles = _roles(scenario)
        self.every = max(1, round(1.0 / (rate_hz * scenario.dt_s)))
        self.columns, _ = recording_layout(list(scenario.components.values()))
        self.stream = ViewStream(
            scene_of(scenario),
            title=scenario.name,
            timeline=TIMELINE,
            web_port=web_port,
            record=record,
        )
        self.url = self.stream.url
        self.batch = max(1, round(0.25 * rate_hz)) if web_port is not None else 1000
        self._rows: list[np.ndarray] = []
        self._times: list[float] = []
        self._ticked = False
        if not self.roles:
            self.stream.text(
                0.0, f"{scenario.name}: no arm's pose among its components: nothing to show"
            )

    def tick(self, k: int, t: float, outputs: np.ndarray) -> None:
        """After tick k: every `every`-th row (time t + dt) kept, sent in blocks."""
        self._ticked = True
        if (k + 1) % self.every or not self.roles:
            return
        self._rows.append(outputs.copy())
        self._times.append((k + 1) * self.scenario.dt_s)
        if len(self._rows) >= self.batch:
            self._send()

    def _send(self) -> None:
        if not self._rows:
            return
        block = np.array(self._rows)
        times = np.array(self._times)
        self._rows, self._times = [], []
        self.stream.log(signals_track(self.roles, times, lambda name: block[:, self.columns[name]]))

    def done(self, rec: Any) -> None:
        """The run has ended and its results are written: the rest (all of it, when the engine
        stepped on its own), then the recording into place."""
        if not self._ticked and self.roles:  # the rows the ticks would have kept: every-th on
            rows = slice(self.every, None, self.every)
            for start in range(0, len(rec.time[rows]), 1000):
                first = (start + 1) * self.every
                chunk = slice(first, first + 1000 * self.every, self.every)
                self.stream.log(
                    signals_track(self.roles, rec.time[chunk], lambda n, chunk=chunk: rec[n][chunk])
                )
        self._send()
        self.stream.finish()

    def abandon(self) -> None:
        self.stream.abandon()

    def close(self) -> None:
        self.stream.close()


def record_signals(
    scenario: Any,
    time: np.ndarray,
    signals: Mapping[str, np.ndarray],
    path: str | Path,
    *,
    title: str | None = None,
    texts: Sequence[tuple[float, str]] = (),
) -> Path | None:
    """A recording of a run's kept signals (rows at `time`, e.g. a study's kept runs; a row at 0,
    the outputs before the first step, left out as a live view has it): None when the scenario
    has nothing to show."""
    roles = {c: name for c, name in _roles(scenario).items() if name in signals}
    if "p_BT_B" not in roles or "R_BT" not in roles:
        return None
    stream = ViewStream(
        scene_of(scenario), title=title or scenario.name, timeline=TIMELINE, record=path
    )
    skip = 1 if len(time) and time[0] == 0.0 else 0
    try:
        for t, text in texts:
            stream.text(t, text)
        for start in range(skip, len(time), 1000):
            rows = slice(start, start + 1000)
            stream.log(signals_track(roles, time[rows], lambda n, rows=rows: signals[n][rows]))
        return stream.finish()
    finally:
        stream.close()
