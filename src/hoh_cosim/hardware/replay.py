"""`hoh-cosim replay LOG.mcap [--set ...]`: the estimator and controller again, on recorded data.

A session log holds, for every cycle, exactly what the estimator and the controller were given (the
raw FT-150 and FSE103 samples with their counters, the robot's pose at the resolution the loop
itself works with) and the parameters they ran with. Replaying feeds the same inputs to fresh blocks
with other settings and compares the new estimates and commands with the recorded ones: that is how
one tunes on real data. The log holds estimates and commands at a resolution (1 mN, 0.1 mm/s; see
`session_log.RESOLUTION`), and the replay's are rounded alike before the comparison: without
`--set` the replay reproduces the recording exactly (a test holds it to that).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.cycle import ControlBlocks, Reading, control_cycle
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.supervisor import SessionPolicy
from hoh_cosim.errors import ConfigError, InputFileError
from hoh_cosim.hardware.config import with_overrides
from hoh_cosim.hardware.session_log import FLOAT32, RESOLUTION, Session, read_session
from hoh_cosim.params import with_values
from hoh_cosim.presets import changed_from, load_preset

__all__ = ["ReplayResult", "replay", "replay_parameters"]


@dataclass
class ReplayResult:
    session: Session
    t: np.ndarray
    old: dict[str, np.ndarray]  # recorded: F_hand_B, twist_B, status
    new: dict[str, np.ndarray]  # replayed
    estimator: EstimatorParams
    controller: ControllerParams
    cycles: np.ndarray | None = None  # the cycle number k of each row

    def summary(self) -> dict[str, Any]:
        dv = self.new["twist_B"][:, :3] - self.old["twist_B"][:, :3]
        dF = self.new["F_hand_B"] - self.old["F_hand_B"]
        speed = {
            k: np.linalg.norm(v["twist_B"][:, :3], axis=1)
            for k, v in (("old", self.old), ("new", self.new))
        }
        return {
            "cycles": len(self.t),
            "complete_log": self.session.complete,
            "speed_rms_old_m_s": float(np.sqrt(np.mean(speed["old"] ** 2))),
            "speed_rms_new_m_s": float(np.sqrt(np.mean(speed["new"] ** 2))),
            "twist_difference_max_m_s": float(np.max(np.linalg.norm(dv, axis=1))),
            "hand_force_difference_rms_N": float(np.sqrt(np.mean(np.sum(dF * dF, axis=1)))),
            "stops_old": int(np.count_nonzero(self.old["status"] & 0xF00)),
            "stops_new": int(np.count_nonzero(self.new["status"] & 0xF00)),
        }


def replay_parameters(
    session: Session, preset: str | Path | None = None
) -> tuple[EstimatorParams, ControllerParams, float]:
    """The estimator's and controller's parameters and the period the session ran with; with
    `preset`, that preset's parameters with the session's changes from its own preset (a log
    without a preset: from the blocks' defaults)."""
    recorded = [m for m in session.messages.get("/events", []) if m.get("event") == "parameters"]
    if not recorded:
        raise InputFileError(
            session.path, "/events", "no 'parameters' event: the session ended before its loop"
        )
    p = json.loads(recorded[0]["detail"])
    try:
        estimator = with_values(EstimatorParams(), p["estimator"])
        controller = with_values(ControllerParams(), p["controller"])
    except ConfigError as exc:
        raise InputFileError(session.path, "/events parameters", str(exc)) from None
    if preset is not None:
        chosen = load_preset(preset)
        own = p.get("preset")
        before = load_preset(own) if own else None
        try:
            estimator, controller = (
                with_values(
                    chosen.params[block],
                    changed_from(before.params[block] if before else type(params)(), params),
                )
                for block, params in (("estimator", estimator), ("controller", controller))
            )
        except ConfigError as exc:
            raise ConfigError(f"--preset {chosen.label}: {exc}") from None
    return estimator, controller, float(p["period_s"])


def _by_cycle(session: Session, topic: str) -> dict[int, dict[str, Any]]:
    return {m["k"]: m for m in session.messages.get(topic, [])}


def _latest_by_cycle(session: Session, topic: str, cycles: list[int]) -> dict[int, dict[str, Any]]:
    """A sensor's message for each cycle: the latest at or before it (a sensor's channel has a
    message when a new sample came; older logs have one every cycle, which this reads alike)."""
    messages = sorted(session.messages.get(topic, []), key=lambda m: m["k"])
    out: dict[int, dict[str, Any]] = {}
    i, latest = 0, None
    for k in cycles:
        while i < len(messages) and messages[i]["k"] <= k:
            latest = messages[i]
            i += 1
        if latest is not None:
            out[k] = latest
    return out


def _probe_force(values: list[Any], resolved: bool) -> np.ndarray:
    """The FSE103's force as the loop had it: float32 on the wire, logged as its shortest decimal."""
    force = _vector(values)
    if resolved and RESOLUTION.get(("/fse103", "force_P")) == FLOAT32:
        return force.astype(np.float32).astype(np.float64)
    return force


def _orientation(robot: dict[str, Any]) -> np.ndarray:
    """R_BT of a /robot message: from its rotation vector (older logs: the matrix, row by row)."""
    if "rotvec_BT" in robot:
        return rotvec_to_matrix(_vector(robot["rotvec_BT"]))
    return _vector(robot["R_BT"]).reshape(3, 3)


def _vector(values: list[Any]) -> np.ndarray:
    return np.array([math.nan if x is None else x for x in values], dtype=float)


def replay(
    path: str | Path, overrides: Sequence[str] = (), preset: str | Path | None = None
) -> ReplayResult:
    """Replay a session log with `overrides` (`estimator.x=v`, `controller.x=v`), and with
    `preset` (`--preset`) the session as it would have run with that preset: the preset's
    parameters with what the session changed from its own (the rig's file, its `--set`, the
    calibration's tool, the sensors), then the overrides."""
    session = read_session(path)
    estimator_params, controller_params, period = replay_parameters(session, preset)
    params = with_overrides(
        {"estimator": estimator_params, "controller": controller_params}, overrides
    )
    R_TS = np.asarray(session.metadata.get("R_TS", np.eye(3)), dtype=float)
    robot = _by_cycle(session, "/robot")
    estimates, commands = _by_cycle(session, "/estimate"), _by_cycle(session, "/command")
    cycles = sorted(k for k in commands if k in robot and k in estimates)
    if not cycles:
        raise InputFileError(session.path, "/command", "no control cycle was recorded")
    ft, probe = (_latest_by_cycle(session, t, cycles) for t in ("/ft150", "/fse103"))
    # a log that holds its numbers at a resolution (its orientation as a rotation vector) is
    # compared at that resolution: a replay that reproduces the session differs by nothing
    resolved = "rotvec_BT" in robot[cycles[0]]

    def at_resolution(values: np.ndarray, topic: str, name: str) -> np.ndarray:
        decimals = RESOLUTION.get((topic, name))
        if not resolved or not isinstance(decimals, int):
            return values.copy()
        return np.round(values, decimals) + 0.0

    blocks = ControlBlocks(
        Estimator(params["estimator"]),
        HandGuidingController(params["controller"]),
        SessionPolicy(params["controller"].limits),
    )
    old: dict[str, list[Any]] = {"F_hand_B": [], "twist_B": [], "status": []}
    new: dict[str, list[Any]] = {"F_hand_B": [], "twist_B": [], "status": []}
    t_list = []
    for k in cycles:
        r, f, pr = robot[k], ft.get(k), probe.get(k)
        t = k * period
        reading = Reading(
            _vector(r["p_BT_B"]),
            _orientation(r) @ R_TS,
            _vector(f["wrench_S"]) if f else None,
            int(f["count"]) if f else 0,
            _probe_force(pr["force_P"], resolved) if pr else None,
            int(pr["count"]) if pr else 0,
        )
        cycle = control_cycle(blocks, reading, t, period)
        t_list.append(t)
        old["F_hand_B"].append(_vector(estimates[k]["F_hand_B"]))
        old["twist_B"].append(_vector(commands[k]["twist_B"]))
        old["status"].append(int(commands[k]["status"]))
        new["F_hand_B"].append(at_resolution(cycle.estimate["F_hand_B"], "/estimate", "F_hand_B"))
        new["twist_B"].append(at_resolution(cycle.command["twist_B"], "/command", "twist_B"))
        new["status"].append(int(cycle.command["status"][0]))
    return ReplayResult(
        session,
        np.array(t_list),
        {k: np.array(v) for k, v in old.items()},
        {k: np.array(v) for k, v in new.items()},
        params["estimator"],
        params["controller"],
        np.array(cycles),
    )


def plot_replay(result: ReplayResult) -> bytes:
    """Recorded against replayed: the hand-force estimate and the commanded velocity."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, sharex=True, figsize=(12, 6))
    for j, axis in enumerate("xyz"):
        axes[0, j].plot(result.t, result.old["F_hand_B"][:, j], lw=0.8, label="recorded")
        axes[0, j].plot(result.t, result.new["F_hand_B"][:, j], lw=0.8, label="replayed")
        axes[0, j].set_ylabel(f"F_hand {axis} [N]")
        axes[1, j].plot(result.t, 1e3 * result.old["twist_B"][:, j], lw=0.8, label="recorded")
        axes[1, j].plot(result.t, 1e3 * result.new["twist_B"][:, j], lw=0.8, label="replayed")
        axes[1, j].set_ylabel(f"v {axis} [mm/s]")
        axes[1, j].set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{result.session.path.name}: recorded and replayed")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return buffer.getvalue()
