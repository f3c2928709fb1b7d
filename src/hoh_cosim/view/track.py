"""What the view shows, one row per shown instant, whatever produced it: a run, a robot session, a
replay.

A `Track` is columns over time, everything in the base frame B: the TCP pose, the joints where
they are known, the hand's force, the contact force, the commanded twist, the tip's velocity, the
path's reference, the breath's offset of the surface, the controller's status and mode. A column
that the source does not have is None, and the view leaves out what it would have drawn from it.

Sources:
- a co-simulation's signals (`cosim_roles` names which component's port gives which column: the
  arm's, the operator's, the estimator's, the controller's, the breathing's), the hand's and the
  contact's forces the true ones, the estimator's hand force beside them;
- the hardware runner's cycle rows (`hoh_cosim.hardware.session_log.CYCLE_LAYOUT`) and a session
  log read back: the forces are the estimator's (the robot knows no others), the twist the one
  sent, the joints found from the logged TCP pose (`scene.ArmTracker`);
- a replay: the session's columns and the recomputed command beside the logged one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "COSIM_ROLES",
    "Track",
    "cosim_roles",
    "rows_track",
    "session_track",
]


@dataclass
class Track:
    """Columns over the shown instants `t` [s] (n rows); None: the source does not give it."""

    t: np.ndarray  # (n,)
    p_BT_B: np.ndarray  # (n, 3) the TCP (the probe's tip) [m]
    R_BT: np.ndarray  # (n, 3, 3) its orientation
    q: np.ndarray | None = None  # (n, 6) the UR5's joints [rad]
    F_hand_B: np.ndarray | None = None  # (n, 3) the hand's force on the handle [N]
    F_hand_est_B: np.ndarray | None = None  # (n, 3) the estimator's, beside a true one [N]
    F_contact_B: np.ndarray | None = None  # (n, 3) the surface's force on the tip [N]
    twist_cmd_B: np.ndarray | None = None  # (n, 6) the commanded TCP twist [m/s, rad/s]
    twist_replayed_B: np.ndarray | None = None  # (n, 6) a replay's recomputed command
    v_B: np.ndarray | None = None  # (n, 3) the tip's velocity [m/s]
    p_ref_B: np.ndarray | None = None  # (n, 3) where the path wants the tip [m]
    surface_offset_m: np.ndarray | None = None  # (n,) the surface moved along its normal [m]
    status: np.ndarray | None = None  # (n,) the controller's status bits (Status)
    mode: np.ndarray | None = None  # (n,) the controller's mode (Mode)

    def __len__(self) -> int:
        return len(self.t)

    def rows(self, index: slice | np.ndarray) -> Track:
        """The rows at `index`, as a track of their own."""
        return Track(
            **{
                f.name: None if (v := getattr(self, f.name)) is None else v[index]
                for f in dataclasses.fields(self)
            }
        )

    @classmethod
    def concatenate(cls, tracks: Sequence[Track]) -> Track:
        """One track of several in order; a column is kept only if every one has it."""
        out = {}
        for f in dataclasses.fields(cls):
            parts = [getattr(t, f.name) for t in tracks]
            out[f.name] = None if any(p is None for p in parts) else np.concatenate(parts)
        return cls(**out)


# --- a co-simulation ---------------------------------------------------------------------------

COSIM_ROLES: dict[str, tuple[tuple[str, str], ...]] = {
    # column: (component kind, port) in order of preference
    "p_BT_B": (("plant", "p_BT_B"), ("panda", "p_BT_B"), ("freehand", "p_BT_B")),
    "R_BT": (("plant", "R_BT"), ("panda", "R_BT"), ("freehand", "R_BT")),
    "q": (("plant", "q"),),
    "v_B": (("plant", "twist_B"), ("panda", "twist_B"), ("freehand", "twist_B")),
    "F_contact_B": (
        ("plant", "F_contact_B"),
        ("panda", "F_contact_B"),
        ("freehand", "F_contact_B"),
    ),
    "F_hand_B": (("operator", "F_hand_B"),),
    "F_hand_est_B": (("estimator", "F_hand_B"),),
    "twist_cmd_B": (("controller", "twist_B"), ("ur5_impedance", "twist_B")),
    "p_ref_B": (
        ("operator", "p_ref_B"),
        ("ur5_impedance", "p_ref_B"),
        ("impedance", "p_ref_B"),
    ),
    "surface_offset_m": (("breathing", "offset_m"),),
    "status": (("controller", "status"),),
    "mode": (("controller", "mode"),),
}
"""Which component's port gives each column of a run's track, by the component's kind."""


def cosim_roles(kinds: Mapping[str, str]) -> dict[str, str]:
    """column -> "component.port" for a scenario whose components are `kinds` (name -> kind), the
    first of each column's candidates that the scenario has. A scenario without an arm's pose has
    nothing to show: an empty dict."""
    by_kind: dict[str, str] = {}
    for name, kind in kinds.items():
        by_kind.setdefault(kind, name)
    roles = {}
    for column, candidates in COSIM_ROLES.items():
        for kind, port in candidates:
            if kind in by_kind:
                roles[column] = f"{by_kind[kind]}.{port}"
                break
    if "p_BT_B" not in roles or "R_BT" not in roles:
        return {}
    return roles


def signals_track(
    roles: Mapping[str, str], t: np.ndarray, signal: Callable[[str], np.ndarray]
) -> Track:
    """A run's track at times `t` from `signal("component.port")` (rows at those times)."""
    columns: dict[str, Any] = {"t": np.asarray(t, dtype=float)}
    for column, name in roles.items():
        values = np.asarray(signal(name), dtype=float)
        if column == "R_BT":
            values = values.reshape(-1, 3, 3)
        elif column == "v_B":
            values = values[:, :3]
        elif column in ("surface_offset_m", "status", "mode"):
            values = values[:, 0]
        columns[column] = values
    return Track(**columns)


# --- a robot session ---------------------------------------------------------------------------


def rows_track(rows: np.ndarray) -> Track:
    """The track of the runner's cycle rows (n, ROW_SIZE) as its feed hands them over (the
    session log's `CycleRow` layout: k, t, then `CYCLE_LAYOUT`)."""
    from hoh_cosim.control.frames import rotvec_to_matrix
    from hoh_cosim.hardware.session_log import CycleRow

    at = CycleRow().slices
    rows = np.atleast_2d(rows)

    def get(name: str) -> np.ndarray:
        return rows[:, at[name]]

    return Track(
        t=rows[:, 1].copy(),
        p_BT_B=get("/robot.p_BT_B").copy(),
        R_BT=np.array([rotvec_to_matrix(r) for r in get("/robot.rotvec_BT")]).reshape(-1, 3, 3),
        F_hand_B=get("/estimate.F_hand_B").copy(),
        F_contact_B=get("/estimate.F_probe_B").copy(),
        twist_cmd_B=get("/command.sent_B").copy(),
        v_B=get("/robot.twist_B")[:, :3].copy(),
        status=get("/command.status")[:, 0].copy(),
        mode=get("/command.mode")[:, 0].copy(),
    )


def _by_k(messages: Sequence[Mapping[str, Any]]) -> dict[int, Mapping[str, Any]]:
    return {int(m["k"]): m for m in messages}


def session_track(
    session: Any, every_s: float, replayed: Mapping[int, np.ndarray] | None = None
) -> Track:
    """The track of a session log read back (`hoh_cosim.hardware.session_log.Session`), one row
    every `every_s` of session time at most, the twist the one sent; with `replayed` (cycle k ->
    the replay's recomputed controller twist), the controller's logged twist beside it (like with
    like: both before the supervisor's verdict)."""
    from hoh_cosim.control.frames import rotvec_to_matrix

    robot = _by_k(session.messages.get("/robot", []))
    estimate = _by_k(session.messages.get("/estimate", []))
    command = _by_k(session.messages.get("/command", []))
    cycles = sorted(k for k in command if k in robot and k in estimate)
    if replayed is not None:
        cycles = [k for k in cycles if k in replayed]
    chosen, next_t = [], -np.inf
    for k in cycles:
        t = float(command[k]["t"])
        if t >= next_t - 1e-9:
            chosen.append(k)
            next_t = t + every_s

    def vectors(source: Mapping[int, Mapping[str, Any]], name: str) -> np.ndarray:
        return np.array(
            [[np.nan if x is None else x for x in source[k][name]] for k in chosen], dtype=float
        ).reshape(len(chosen), -1)

    def rotation(k: int) -> np.ndarray:
        r = robot[k]
        if "rotvec_BT" in r:
            return rotvec_to_matrix(np.asarray(r["rotvec_BT"], dtype=float))
        return np.asarray(r["R_BT"], dtype=float).reshape(3, 3)  # older logs

    return Track(
        t=np.array([float(command[k]["t"]) for k in chosen]),
        p_BT_B=vectors(robot, "p_BT_B"),
        R_BT=np.array([rotation(k) for k in chosen]).reshape(len(chosen), 3, 3),
        F_hand_B=vectors(estimate, "F_hand_B"),
        F_contact_B=vectors(estimate, "F_probe_B"),
        twist_cmd_B=vectors(command, "sent_B" if replayed is None else "twist_B"),
        twist_replayed_B=None
        if replayed is None
        else np.array([replayed[k] for k in chosen]).reshape(len(chosen), 6),
        v_B=vectors(robot, "twist_B")[:, :3],
        status=np.array([int(command[k]["status"]) for k in chosen], dtype=float),
        mode=np.array([int(command[k]["mode"]) for k in chosen], dtype=float),
    )
