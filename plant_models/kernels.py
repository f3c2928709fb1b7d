"""The plant models' compiled kernels (numba): the UR5's kinematics and its tool frames, checked
against pinocchio; and checked against their pure code, the phantom's contact with the sensors'
readings (`contact_loads`), an FT-150 packet (`ft_packet`, to the bit) and the freehand probe's
implicit step (`freehand_step`).

The plant asks, at every tick the arm moves, for the placements of the TCP and the wrist sensor, the
TCP's twist and the classical accelerations of the tool's centre of mass and of the probe sensor;
at every robot cycle for the TCP's Jacobian. Through pinocchio that is five calls of 1-5 µs each,
most of it call overhead on a six-joint chain. `KernelUR5` computes all of it in one compiled call
from the same geometry: the joint and frame placements are read from the pinocchio model
(`UR5Model`), which stays the reference (tests compare the two to 1e-12).

The chain, in the base frame B (every joint a revolute about its own z; joint i's placement
(R_i, p_i) in its parent's frame, then Rz(q_i)):

    R ← R R_i Rz(q_i) ;  o_i = o + R p_i ;  z_i = R e_z
    v_i = v + ω × r ;  a_i = a + α × r + ω × (ω × r)          (r = o_i - o, the origin's velocity
                                                                 and classical acceleration)
    α ← α + z_i q̈_i + q̇_i (ω × z_i) ;  ω ← ω + z_i q̇_i

and a frame fixed to the last link at (R_f, p_f) the same way with r = R p_f. The Jacobian of a
frame's origin (LOCAL_WORLD_ALIGNED, [v; ω]) has the columns [z_i × (p_f - o_i); z_i].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hoh_cosim.control.jit import njit, types
from hoh_cosim.control.kernels import kernels_enabled
from hoh_cosim.errors import ConfigError
from plant_models.ur5 import chain_geometry

__all__ = ["KINEMATICS_LAYOUT", "KernelUR5", "kernels_enabled"]

_IN = types.Array(types.float64, 1, "A", readonly=True)
"""An input vector of any layout, writable or not: one compiled version for every caller (a
scenario's buffers, a rehearsal world's read-only zeros), never a compile in a running loop."""
_OUT = types.Array(types.float64, 1, "C")

KINEMATICS_LAYOUT = {
    "pose_T": slice(0, 12),  # p_BT_B, then R_BT row by row
    "pose_S": slice(12, 24),  # p_BS_B, then R_BS row by row
    "twist_T": slice(24, 30),  # [v; ω] of the TCP in B
    "accel_C": slice(30, 36),  # [a_C; α] of the tool's centre of mass in B
    "accel_P": slice(36, 39),  # a of the probe sensor's origin in B
}
"""Where each quantity sits in `KernelUR5.tool_kinematics`'s array."""


@njit(cache=True, nogil=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, nogil=True)
def _chain(G, nj, q, qd, qdd, with_motion, R, o, v, a, w, al, z, origins):  # pragma: no cover
    """The last joint's frame (R, o), and with `with_motion` its origin's v, a and the link's ω, α,
    written into the arrays given; every joint's axis z and origin into `z` and `origins`. Joint i's
    placement is G[i]: R_i row by row, then p_i."""
    R[:, :] = 0.0
    R[0, 0] = R[1, 1] = R[2, 2] = 1.0
    o[:] = 0.0
    v[:] = 0.0
    a[:] = 0.0
    w[:] = 0.0
    al[:] = 0.0
    M = np.empty((3, 3))
    for i in range(nj):
        # r = R p_i : the joint's origin from the previous one
        g = G[i]
        r0 = R[0, 0] * g[9] + R[0, 1] * g[10] + R[0, 2] * g[11]
        r1 = R[1, 0] * g[9] + R[1, 1] * g[10] + R[1, 2] * g[11]
        r2 = R[2, 0] * g[9] + R[2, 1] * g[10] + R[2, 2] * g[11]
        o[0] += r0
        o[1] += r1
        o[2] += r2
        # M = R R_i
        for m in range(3):
            for n in range(3):
                M[m, n] = R[m, 0] * g[n] + R[m, 1] * g[3 + n] + R[m, 2] * g[6 + n]
        # R ← M Rz(q): columns x' = c x + s y, y' = -s x + c y, z' = z
        c, s = np.cos(q[i]), np.sin(q[i])
        for m in range(3):
            R[m, 0] = c * M[m, 0] + s * M[m, 1]
            R[m, 1] = -s * M[m, 0] + c * M[m, 1]
            R[m, 2] = M[m, 2]
        z0, z1, z2 = M[0, 2], M[1, 2], M[2, 2]
        z[i, 0], z[i, 1], z[i, 2] = z0, z1, z2
        origins[i, 0], origins[i, 1], origins[i, 2] = o[0], o[1], o[2]
        if with_motion:
            w0, w1, w2 = w[0], w[1], w[2]
            c0, c1, c2 = _cross(w0, w1, w2, r0, r1, r2)  # ω × r
            d0, d1, d2 = _cross(al[0], al[1], al[2], r0, r1, r2)  # α × r
            e0, e1, e2 = _cross(w0, w1, w2, c0, c1, c2)  # ω × (ω × r)
            v[0] += c0
            v[1] += c1
            v[2] += c2
            a[0] += d0 + e0
            a[1] += d1 + e1
            a[2] += d2 + e2
            f0, f1, f2 = _cross(w0, w1, w2, z0, z1, z2)  # ω × z
            al[0] += z0 * qdd[i] + qd[i] * f0
            al[1] += z1 * qdd[i] + qd[i] * f1
            al[2] += z2 * qdd[i] + qd[i] * f2
            w[0] += z0 * qd[i]
            w[1] += z1 * qd[i]
            w[2] += z2 * qd[i]


@njit(cache=True, nogil=True, inline="always")
def _frame(R, o, v, a, w, al, g, out, at):  # pragma: no cover - compiled
    """A frame at g = (R_f row by row, p_f) in the last joint's frame: its pose [p; R row by row]
    into out[at:at+12] (if at >= 0); returns its origin's (v, a) as two 3-tuples."""
    r0 = R[0, 0] * g[9] + R[0, 1] * g[10] + R[0, 2] * g[11]
    r1 = R[1, 0] * g[9] + R[1, 1] * g[10] + R[1, 2] * g[11]
    r2 = R[2, 0] * g[9] + R[2, 1] * g[10] + R[2, 2] * g[11]
    if at >= 0:
        out[at], out[at + 1], out[at + 2] = o[0] + r0, o[1] + r1, o[2] + r2
        for m in range(3):
            for n in range(3):
                out[at + 3 + 3 * m + n] = R[m, 0] * g[n] + R[m, 1] * g[3 + n] + R[m, 2] * g[6 + n]
    w0, w1, w2 = w[0], w[1], w[2]
    c0, c1, c2 = _cross(w0, w1, w2, r0, r1, r2)
    d0, d1, d2 = _cross(al[0], al[1], al[2], r0, r1, r2)
    e0, e1, e2 = _cross(w0, w1, w2, c0, c1, c2)
    return (v[0] + c0, v[1] + c1, v[2] + c2), (a[0] + d0 + e0, a[1] + d1 + e1, a[2] + d2 + e2)


@njit(cache=True, nogil=True)
def _tool_kinematics(G, state, out):  # pragma: no cover - compiled
    """KINEMATICS_LAYOUT's 39 values at state = [q; q̇; q̈] (3 n) into `out`; G: the n joints'
    placements, then the TCP's, the wrist sensor's, the tool's centre of mass's and the probe
    sensor's. (The callers make `out`: a compiled function's own new array costs twice as much to
    return.)"""
    R = np.empty((3, 3))
    o, v, a, w, al = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    nj = G.shape[0] - 4
    z, origins = np.empty((nj, 3)), np.empty((nj, 3))
    q, qd, qdd = state[:nj], state[nj : 2 * nj], state[2 * nj : 3 * nj]
    _chain(G, nj, q, qd, qdd, True, R, o, v, a, w, al, z, origins)
    vT, _ = _frame(R, o, v, a, w, al, G[nj], out, 0)
    out[24], out[25], out[26] = vT
    out[27], out[28], out[29] = w[0], w[1], w[2]
    _frame(R, o, v, a, w, al, G[nj + 1], out, 12)
    _, aC = _frame(R, o, v, a, w, al, G[nj + 2], out, -1)
    out[30], out[31], out[32] = aC
    out[33], out[34], out[35] = al[0], al[1], al[2]
    _, aP = _frame(R, o, v, a, w, al, G[nj + 3], out, -1)
    out[36], out[37], out[38] = aP


@njit(cache=True, nogil=True)
def _jacobian(G, frame, q, J):  # pragma: no cover - compiled
    """6 x n Jacobian of [v; ω] of frame G[frame]'s origin in B: columns [z_i × (p - o_i); z_i]."""
    R = np.empty((3, 3))
    o, v, a, w, al = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    nj = q.shape[0]
    z, origins = np.empty((nj, 3)), np.empty((nj, 3))
    _chain(G, nj, q, q, q, False, R, o, v, a, w, al, z, origins)
    g = G[frame]
    p0 = o[0] + (R[0, 0] * g[9] + R[0, 1] * g[10] + R[0, 2] * g[11])
    p1 = o[1] + (R[1, 0] * g[9] + R[1, 1] * g[10] + R[1, 2] * g[11])
    p2 = o[2] + (R[2, 0] * g[9] + R[2, 1] * g[10] + R[2, 2] * g[11])
    for i in range(nj):
        c0, c1, c2 = _cross(
            z[i, 0], z[i, 1], z[i, 2], p0 - origins[i, 0], p1 - origins[i, 1], p2 - origins[i, 2]
        )
        J[0, i], J[1, i], J[2, i] = c0, c1, c2
        J[3, i], J[4, i], J[5, i] = z[i, 0], z[i, 1], z[i, 2]


def _pinocchio_geometry(model: Any) -> tuple[list[np.ndarray], dict[str, np.ndarray]]:
    """A `UR5Model`'s joint placements and its frames in the last joint's frame, as 4x4
    transforms (as `ur5.chain_geometry` gives them)."""
    pin_model = model.model
    joints = range(1, pin_model.njoints)
    for j in joints:
        if pin_model.joints[j].shortname() != "JointModelRZ" or pin_model.parents[j] != j - 1:
            raise ConfigError("KernelUR5: expected a chain of revolute joints about z")
    last = pin_model.njoints - 1
    frames = {}
    for name, fid in model.frame_ids.items():
        frame = pin_model.frames[fid]
        if frame.parentJoint != last:
            raise ConfigError(f"KernelUR5: frame {name} is not fixed to the last link")
        frames[name] = np.asarray(frame.placement.homogeneous)
    return [np.asarray(pin_model.jointPlacements[j].homogeneous) for j in joints], frames


class KernelUR5:
    """The kinematics a `UR5Model` gives the plant, compiled, from that model's own placements.

    `tool_kinematics(q, q̇, q̈)`: one new array laid out as `KINEMATICS_LAYOUT`;
    `jacobian(q, frame)`: as `UR5Model.jacobian`, for the frames the model has.
    """

    TOOL_FRAMES = ("tcp", "ft_sensor", "tool_com", "probe_sensor")

    def __init__(self, model: object | None = None, tool_frames: tuple[Any, ...] = ()) -> None:
        """From a `UR5Model`'s placements (pinocchio's, the reference), or, with `model` None, from
        `ur5.chain_geometry(tool_frames)` (no pinocchio needed: an FMU's host)."""
        if model is not None:
            joint_placements, frames = _pinocchio_geometry(model)
        else:
            joint_placements, frames = chain_geometry(tuple(tool_frames))
        # absent tool frames (a bare arm) read as the flange; then every other frame, by name
        tool = [frames.get(name, frames["flange"]) for name in self.TOOL_FRAMES]
        self.frame_ids = {name: i for i, name in enumerate(frames)}
        self._rows = {name: len(joint_placements) + 4 + i for i, name in enumerate(frames)}
        self._G = np.array(
            [
                np.concatenate([T[:3, :3].ravel(), T[:3, 3]])
                for T in (*joint_placements, *tool, *frames.values())
            ]
        )
        self._nj = len(joint_placements)
        self._G_tool = self._G[: self._nj + 4].copy()
        self.nq = self._nj

    def tool_kinematics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        return self.tool_kinematics_at(np.concatenate([q, qd, qdd]))

    def tool_kinematics_at(self, state: np.ndarray) -> np.ndarray:
        """`tool_kinematics` of the arm's state [q; q̇; q̈] as one array (`SpeedLArm.state`)."""
        out = np.empty(39)
        _tool_kinematics(self._G_tool, state, out)
        return out

    def jacobian(self, q: np.ndarray, frame: str) -> np.ndarray:
        J = np.empty((6, self.nq))
        _jacobian(self._G, self._rows[frame], np.asarray(q, dtype=np.float64), J)
        return J

    def warm_up(self) -> None:
        """Load (or compile) the kernels now, so that no tick waits for it."""
        zero = np.zeros(self.nq)
        k = self.tool_kinematics(zero, zero, zero)
        self.jacobian(zero, "flange")
        contact_loads(np.zeros(35), k, np.full(19, 2.0), *(np.zeros(3),) * 3, *(np.zeros(1),) * 2)
        if self.nq == 6:
            arm_cycle(self, "flange", np.zeros(18), *(np.zeros(6),) * 2, np.zeros(39), np.ones(8))
            arm_advance(np.zeros(18), np.zeros(6), 1e-3, 1e-3)


# --- what the ideal sensors read (tool.ToolLoads.readings) --------------------------------------


def loads_constants(tool: object, g_B: np.ndarray) -> np.ndarray:
    """`_loads`'s constants from a `ToolModel` and gravity: m, g_B, p_SH, p_ST, p_SC, the
    diagonal inertia, R_PS row by row, whether the cable pulls, p_SK, its anchor, its tension, its
    hanging weight, the probe's mass (35 values)."""
    cable = tool.cable  # type: ignore[attr-defined]
    return np.array(
        [
            tool.mass_kg,  # type: ignore[attr-defined]
            *np.asarray(g_B, dtype=np.float64).tolist(),
            *tool.p_SH_S.tolist(),  # type: ignore[attr-defined]
            *tool.p_ST_S.tolist(),  # type: ignore[attr-defined]
            *tool.p_SC_S.tolist(),  # type: ignore[attr-defined]
            *tool.inertia_C_S.tolist(),  # type: ignore[attr-defined]
            *tool.R_SP.T.ravel().tolist(),  # type: ignore[attr-defined]
            1.0 if cable.enabled else 0.0,
            *cable.p_SK_S.tolist(),
            *cable.anchor_B.tolist(),
            cable.tension_N,
            cable.hanging_weight_N,
            tool.probe_mass_kg,  # type: ignore[attr-defined]
        ]
    )


@njit(cache=True, nogil=True, inline="always")
def _loads(C, k, F_hand, tau_hand, F_contact, out):  # pragma: no cover - compiled
    """(wrench of the tool on the wrist sensor in S, force of the probe on the probe sensor in P)
    into `out[:9]`, from the kinematics `k` (KINEMATICS_LAYOUT) and the loads in B:

        f = F_hand + F_contact + F_cable + m (g - a_C)
        τ_S = τ_hand + p_SH × F_hand + p_ST × F_contact + p_SK × F_cable + p_SC × m (g - a_C)
              - (I α + ω × I ω)                     (in S, I diagonal; every vector turned into S)
        F_P = R_PS (F_contact + m_P (g - a_P))     (in S, then P)
    """
    m = C[0]
    g0, g1, g2 = C[1], C[2], C[3]
    R = k[15:24]  # R_BS row by row: v_S = R_BSᵀ v_B, v_S[j] = Σᵢ R[3 i + j] v_B[i]
    rows_B = np.empty((6, 3))
    for i in range(3):
        rows_B[0, i] = F_hand[i]
        rows_B[1, i] = F_contact[i]
        rows_B[2, i] = m * (C[1 + i] - k[30 + i])
        rows_B[3, i] = tau_hand[i]
        rows_B[4, i] = k[27 + i]  # ω
        rows_B[5, i] = k[33 + i]  # α
    S = np.empty((6, 3))
    for r in range(6):
        for j in range(3):
            S[r, j] = rows_B[r, 0] * R[j] + rows_B[r, 1] * R[3 + j] + rows_B[r, 2] * R[6 + j]
    f0 = S[0, 0] + S[1, 0] + S[2, 0]
    f1 = S[0, 1] + S[1, 1] + S[2, 1]
    f2 = S[0, 2] + S[1, 2] + S[2, 2]
    r0 = r1 = r2 = 0.0
    for a in range(3):  # p_SH × F_hand + p_ST × F_contact + p_SC × m (g - a_C)
        p0, p1, p2 = C[4 + 3 * a], C[5 + 3 * a], C[6 + 3 * a]
        c0, c1, c2 = _cross(p0, p1, p2, S[a, 0], S[a, 1], S[a, 2])
        r0 += c0
        r1 += c1
        r2 += c2
    ix, iy, iz = C[13], C[14], C[15]
    wx, wy, wz = S[4, 0], S[4, 1], S[4, 2]
    ax, ay, az = S[5, 0], S[5, 1], S[5, 2]
    tau0 = S[3, 0] + r0 - (ix * ax + (iz - iy) * wy * wz)
    tau1 = S[3, 1] + r1 - (iy * ay + (ix - iz) * wz * wx)
    tau2 = S[3, 2] + r2 - (iz * az + (iy - ix) * wx * wy)
    if C[25] != 0.0:  # the cable, from K = p_BS + R_BS p_SK to its anchor, plus its weight
        s0, s1, s2 = C[26], C[27], C[28]
        K0 = k[12] + (R[0] * s0 + R[1] * s1 + R[2] * s2)
        K1 = k[13] + (R[3] * s0 + R[4] * s1 + R[5] * s2)
        K2 = k[14] + (R[6] * s0 + R[7] * s1 + R[8] * s2)
        d0, d1, d2 = C[29] - K0, C[30] - K1, C[31] - K2
        n = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if n > 0.0:
            s = C[32] / n
            d0, d1, d2 = d0 * s, d1 * s, d2 * s
        else:
            d0 = d1 = d2 = 0.0
        h = C[33] / np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        b0, b1, b2 = d0 + g0 * h, d1 + g1 * h, d2 + g2 * h
        k0 = R[0] * b0 + R[3] * b1 + R[6] * b2
        k1 = R[1] * b0 + R[4] * b1 + R[7] * b2
        k2 = R[2] * b0 + R[5] * b1 + R[8] * b2
        f0, f1, f2 = f0 + k0, f1 + k1, f2 + k2
        c0, c1, c2 = _cross(s0, s1, s2, k0, k1, k2)
        tau0, tau1, tau2 = tau0 + c0, tau1 + c1, tau2 + c2
    out[0], out[1], out[2], out[3], out[4], out[5] = f0, f1, f2, tau0, tau1, tau2
    P0, P1, P2 = S[1, 0], S[1, 1], S[1, 2]
    mp = C[34]
    if mp > 0.0:
        b0, b1, b2 = mp * (g0 - k[36]), mp * (g1 - k[37]), mp * (g2 - k[38])
        P0 = P0 + (R[0] * b0 + R[3] * b1 + R[6] * b2)
        P1 = P1 + (R[1] * b0 + R[4] * b1 + R[7] * b2)
        P2 = P2 + (R[2] * b0 + R[5] * b1 + R[8] * b2)
    for i in range(3):
        out[6 + i] = C[16 + 3 * i] * P0 + C[17 + 3 * i] * P1 + C[18 + 3 * i] * P2


# --- the phantom's contact (tissue.contact_force) -----------------------------------------------

PHANTOM_SHAPES = {"plane": 0.0, "ellipsoid": 1.0, "none": 2.0}
"""The phantom's shape as `phantom_constants` codes it."""


def phantom_constants(phantom: object) -> np.ndarray:
    """`_contact`'s constants (19 values) from `PhantomParams`: the shape's code, the plane's point
    and normal, the ellipsoid's centre and axes, k, n, c, μ, b, v_s."""
    ph = phantom
    return np.array(
        [
            PHANTOM_SHAPES[ph.shape],  # type: ignore[attr-defined]
            *ph.plane_point_B.tolist(),  # type: ignore[attr-defined]
            *ph.plane_normal_B.tolist(),  # type: ignore[attr-defined]
            *ph.ellipsoid_center_B.tolist(),  # type: ignore[attr-defined]
            *ph.ellipsoid_axes.tolist(),  # type: ignore[attr-defined]
            ph.stiffness,  # type: ignore[attr-defined]
            ph.exponent,  # type: ignore[attr-defined]
            ph.damping,  # type: ignore[attr-defined]
            ph.friction,  # type: ignore[attr-defined]
            ph.viscous_friction,  # type: ignore[attr-defined]
            ph.stiction_velocity,  # type: ignore[attr-defined]
        ]
    )


@njit(cache=True, nogil=True, inline="always")
def _contact(Ph, p0, p1, p2, v0, v1, v2, offset, rate):  # pragma: no cover - compiled
    """`tissue.contact_force` of the phantom `Ph` (`phantom_constants`) on a tip at p moving at v,
    the surface `offset` along its normal at `rate`: the force, the depth (with the offset), and
    for the freehand probe's Jacobians the normal n, k δⁿ, δ̇, v's part across n and its size."""
    shape = Ph[0]
    n0, n1, n2 = 0.0, 0.0, 1.0
    if shape == 0.0:
        n0, n1, n2 = Ph[4], Ph[5], Ph[6]
        depth = (Ph[1] - p0) * n0 + (Ph[2] - p1) * n1 + (Ph[3] - p2) * n2
    elif shape == 1.0:
        u0 = (p0 - Ph[7]) / Ph[10]
        u1 = (p1 - Ph[8]) / Ph[11]
        u2 = (p2 - Ph[9]) / Ph[12]
        fe = u0 * u0 + u1 * u1 + u2 * u2 - 1.0
        g0, g1, g2 = 2.0 * u0 / Ph[10], 2.0 * u1 / Ph[11], 2.0 * u2 / Ph[12]
        g = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        if g == 0.0:  # at the centre: deepest; any direction
            depth = min(Ph[10], Ph[11], Ph[12])
        else:
            depth = -fe / g
            n0, n1, n2 = g0 / g, g1 / g, g2 / g
    else:
        depth = -np.inf
    depth += offset
    fc0 = fc1 = fc2 = 0.0
    v_n = v0 * n0 + v1 * n1 + v2 * n2
    depth_rate = -v_n + rate
    t0, t1, t2 = v0 - v_n * n0, v1 - v_n * n1, v2 - v_n * n2
    speed = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    spring = 0.0
    if depth > 0.0:
        spring = Ph[13] * depth ** Ph[14]
        F_n = max(0.0, spring * (1.0 + 1.5 * Ph[15] * depth_rate))
        fc0, fc1, fc2 = F_n * n0, F_n * n1, F_n * n2
        if speed > 0.0:
            c = Ph[16] * F_n * np.tanh(speed / Ph[18]) / speed + Ph[17]
            fc0, fc1, fc2 = fc0 - c * t0, fc1 - c * t1, fc2 - c * t2
    return fc0, fc1, fc2, depth, n0, n1, n2, spring, depth_rate, t0, t1, t2, speed


@njit(types.void(_IN, _IN, _IN, _IN, _IN, _IN, _IN, _IN, _OUT), cache=True, nogil=True)
def _contact_loads(C, k, Ph, F_hand, tau_hand, F_tip, offset, rate, out):  # pragma: no cover
    """The plant's contact at the TCP (`_contact`) and the sensors' readings under it (`_loads`):
    out = [wrench_S (6); force_P (3); F_contact_B (3); penetration, -1 out of reach]."""
    fc0, fc1, fc2, depth = _contact(Ph, k[0], k[1], k[2], k[24], k[25], k[26], offset[0], rate[0])[
        :4
    ]
    F = np.empty(3)
    F[0], F[1], F[2] = fc0 + F_tip[0], fc1 + F_tip[1], fc2 + F_tip[2]
    _loads(C, k, F_hand, tau_hand, F, out)
    out[9], out[10], out[11] = fc0, fc1, fc2
    out[12] = depth if np.isfinite(depth) else -1.0


def contact_loads(
    constants: np.ndarray,
    kinematics: np.ndarray,
    phantom: np.ndarray,
    F_hand_B: np.ndarray,
    tau_hand_B: np.ndarray,
    F_tip_B: np.ndarray,
    offset: np.ndarray,
    offset_rate: np.ndarray,
) -> np.ndarray:
    """The plant's contact and the sensors' readings in one compiled call (`_contact_loads`): a
    new (13,) array [wrench_S; force_P; F_contact_B; penetration]."""
    out = np.empty(13)
    _contact_loads(
        constants, kinematics, phantom, F_hand_B, tau_hand_B, F_tip_B, offset, offset_rate, out
    )
    return out


# --- a robot cycle of the arm under speedL (arm.SpeedLArm.cycle) --------------------------------


@njit(cache=True, nogil=True)
def _singular_extremes(J):  # pragma: no cover - compiled
    """(σ_min, σ_max) of a square J by one-sided Jacobi (Hestenes): plane rotations of column pairs
    until every pair is orthogonal to rounding, then σ = the columns' norms. Accurate to rounding
    relative to σ_max, like LAPACK's SVD (compiled here in a fraction of the time LAPACK's binding
    takes to compile)."""
    n = J.shape[1]
    A = J.copy()
    for _ in range(60):
        rotated = False
        for i in range(n - 1):
            for j in range(i + 1, n):
                alpha = beta = gamma = 0.0
                for k in range(A.shape[0]):
                    alpha += A[k, i] * A[k, i]
                    beta += A[k, j] * A[k, j]
                    gamma += A[k, i] * A[k, j]
                if gamma == 0.0 or abs(gamma) <= 1e-17 * np.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                t = (1.0 if zeta >= 0.0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
                c = 1.0 / np.sqrt(1.0 + t * t)
                s = c * t
                for k in range(A.shape[0]):
                    a_ki, a_kj = A[k, i], A[k, j]
                    A[k, i] = c * a_ki - s * a_kj
                    A[k, j] = s * a_ki + c * a_kj
        if not rotated:
            break
    lo, hi = np.inf, 0.0
    for j in range(n):
        norm = 0.0
        for k in range(A.shape[0]):
            norm += A[k, j] * A[k, j]
        norm = np.sqrt(norm)
        lo, hi = min(lo, norm), max(hi, norm)
    return lo, hi


@njit(cache=True, nogil=True)
def _solve(A, b):  # pragma: no cover - compiled
    """x with A x = b, A square: LU with partial pivoting (as LAPACK's gesv), on copies."""
    n = A.shape[0]
    M = A.copy()
    x = b.copy()
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(M[r, col]) > abs(M[pivot, col]):
                pivot = r
        if pivot != col:
            for c in range(n):
                M[col, c], M[pivot, c] = M[pivot, c], M[col, c]
            x[col], x[pivot] = x[pivot], x[col]
        for r in range(col + 1, n):
            f = M[r, col] / M[col, col]
            M[r, col] = f
            for c in range(col + 1, n):
                M[r, c] -= f * M[col, c]
            x[r] -= f * x[col]
    for r in range(n - 1, -1, -1):
        total = x[r]
        for c in range(r + 1, n):
            total -= M[r, c] * x[c]
        x[r] = total / M[r, r]
    return x


@njit(cache=True, nogil=True)
def _arm_cycle(G, frame, state, active, robot_twist, svd, P, out):  # pragma: no cover
    """One robot cycle's arithmetic: the tracked twist moved towards the active command (at most
    a·T, a_rot·T), the joint velocities by damped least squares (the SVD skipped when Weyl's bound
    from the last one, kept in `svd` = [J₀ (36), σ_min, σ_max, 1 once taken], already shows
    σ_min ≥ ε), the speed and position limits, and q̈ over the ramp, into out = [twist; q̈] (12).
    P = [a·T, a_rot·T, ε, λ_max, joint speed limit, position limit, T, Weyl margin]."""
    nj = 6
    # _step_towards
    dv0, dv1, dv2 = (
        active[0] - robot_twist[0],
        active[1] - robot_twist[1],
        active[2] - robot_twist[2],
    )
    dw0, dw1, dw2 = (
        active[3] - robot_twist[3],
        active[4] - robot_twist[4],
        active[5] - robot_twist[5],
    )
    n_v = np.sqrt(dv0 * dv0 + dv1 * dv1 + dv2 * dv2)
    n_w = np.sqrt(dw0 * dw0 + dw1 * dw1 + dw2 * dw2)
    for i in range(6):
        out[i] = active[i]
    if not (n_v <= P[0] and n_w <= P[1]):
        if not n_v <= P[0]:
            s = P[0] / n_v
            out[0], out[1], out[2] = (
                robot_twist[0] + dv0 * s,
                robot_twist[1] + dv1 * s,
                robot_twist[2] + dv2 * s,
            )
        if not n_w <= P[1]:
            s = P[1] / n_w
            out[3], out[4], out[5] = (
                robot_twist[3] + dw0 * s,
                robot_twist[4] + dw1 * s,
                robot_twist[5] + dw2 * s,
            )
    twist = out[:6].copy()
    q = state[:nj]
    J = np.empty((6, nj))
    _jacobian(G, frame, q, J)
    threshold, max_damping = P[2], P[3]
    sigma_min = -1.0
    if svd[38] != 0.0:
        total = 0.0
        for i in range(6):
            for j in range(6):
                d = J[i, j] - svd[6 * i + j]
                total += d * d
        bound = svd[36] - np.sqrt(total)
        if bound >= threshold + P[7] * svd[37]:
            sigma_min = bound
    if sigma_min < 0.0:
        lo, hi = _singular_extremes(J)
        for i in range(6):
            for j in range(6):
                svd[6 * i + j] = J[i, j]
        svd[36], svd[37], svd[38] = lo, hi, 1.0
        sigma_min = lo
    if sigma_min >= threshold:
        qd = _solve(J, twist)
    else:
        lam2 = (1.0 - (sigma_min / threshold) ** 2) * max_damping**2
        A = np.empty((6, 6))
        for i in range(6):
            for j in range(6):
                total = 0.0
                for k in range(6):
                    total += J[i, k] * J[j, k]
                A[i, j] = total
            A[i, i] += lam2
        y = _solve(A, twist)
        qd = np.empty(6)
        for i in range(6):
            total = 0.0
            for k in range(6):
                total += J[k, i] * y[k]
            qd[i] = total
    peak = 0.0
    nan = False
    for i in range(nj):
        if np.isnan(qd[i]):
            nan = True
        peak = max(peak, abs(qd[i]))
    if not nan and peak > P[4]:
        s = P[4] / peak
        for i in range(nj):
            qd[i] = qd[i] * s
    T, lim = P[6], P[5]
    for i in range(nj):
        q_end = q[i] + 0.5 * (state[nj + i] + qd[i]) * T
        if (q_end > lim and qd[i] > 0.0) or (q_end < -lim and qd[i] < 0.0):
            qd[i] = 0.0
        out[6 + i] = (qd[i] - state[nj + i]) / T


def arm_cycle(
    model: KernelUR5,
    frame: str,
    state: np.ndarray,
    active: np.ndarray,
    robot_twist: np.ndarray,
    svd: np.ndarray,
    constants: np.ndarray,
) -> np.ndarray:
    """`SpeedLArm.cycle`'s arithmetic compiled (see `_arm_cycle`); [twist (6); q̈ (6)], new."""
    out = np.empty(12)
    _arm_cycle(model._G, model._rows[frame], state, active, robot_twist, svd, constants, out)
    return out


@njit(cache=True, nogil=True)
def _advance(state, qdd, ramp, dt, out):  # pragma: no cover - compiled
    """`SpeedLArm.advance` over dt with the cycle's q̈ for `ramp` of it, into out = [q; q̇; q̈_mean]:
    q ← q + q̇ dt + q̈ (ramp²/2 + ramp (dt - ramp)) ;  q̇ ← q̇ + q̈ ramp ;  q̈_mean = q̈ ramp / dt."""
    c = 0.5 * ramp * ramp + ramp * (dt - ramp)
    k = ramp / dt
    for i in range(6):
        out[i] = state[i] + state[6 + i] * dt + qdd[i] * c
        out[6 + i] = state[6 + i] + qdd[i] * ramp
        out[12 + i] = qdd[i] if ramp == dt else qdd[i] * k


def arm_advance(state: np.ndarray, qdd: np.ndarray, ramp: float, dt: float) -> np.ndarray:
    """`_advance` into a new array."""
    out = np.empty(18)
    _advance(state, qdd, ramp, dt, out)
    return out


# --- the freehand probe (plant_models.freehand) -------------------------------------------------


def freehand_constants(params: object, derived: object) -> np.ndarray:
    """`_freehand_step`'s constants (52 values) from `FreehandParams` and the probe's derived
    quantities (`FreehandProbe`): m, the inertia's diagonal in S, r_CH and r_CT in S, R_BS0 row by
    row, the weight, the grip's K_r and D_r, R_ST row by row, then the phantom's 19
    (`phantom_constants`)."""
    d = derived
    return np.array(
        [
            d._m,  # type: ignore[attr-defined]
            *np.diag(d._I_S).tolist(),  # type: ignore[attr-defined]
            *d._r_CH_S.tolist(),  # type: ignore[attr-defined]
            *d._r_CT_S.tolist(),  # type: ignore[attr-defined]
            *d._R_BS0.ravel().tolist(),  # type: ignore[attr-defined]
            *d._weight.tolist(),  # type: ignore[attr-defined]
            params.grip_stiffness,  # type: ignore[attr-defined]
            params.grip_damping,  # type: ignore[attr-defined]
            *d._R_ST.ravel().tolist(),  # type: ignore[attr-defined]
            *phantom_constants(params.phantom).tolist(),  # type: ignore[attr-defined]
        ]
    )


@njit(cache=True, nogil=True)
def _freehand_forces(P, x, inp, out, f, M, C, K, jac):  # pragma: no cover - compiled
    """`FreehandProbe._evaluate` on the state x = [p_C; R row by row; v; ω]: the outputs into
    `out` (p_T, R_BT, twist, F_contact, penetration, τ_grip), the generalised force into f, and
    with `jac` the mass matrix M and the Jacobians C = -∂f/∂u, K = -∂f/∂x."""
    R = x[3:12]
    v0, v1, v2 = x[12], x[13], x[14]
    w0, w1, w2 = x[15], x[16], x[17]
    # r_CT, r_CH in B; the tip's position and velocity
    rt0 = R[0] * P[7] + R[1] * P[8] + R[2] * P[9]
    rt1 = R[3] * P[7] + R[4] * P[8] + R[5] * P[9]
    rt2 = R[6] * P[7] + R[7] * P[8] + R[8] * P[9]
    rh0 = R[0] * P[4] + R[1] * P[5] + R[2] * P[6]
    rh1 = R[3] * P[4] + R[4] * P[5] + R[5] * P[6]
    rh2 = R[6] * P[4] + R[7] * P[5] + R[8] * P[6]
    p0, p1, p2 = x[0] + rt0, x[1] + rt1, x[2] + rt2
    c0, c1, c2 = _cross(w0, w1, w2, rt0, rt1, rt2)
    vt0, vt1, vt2 = v0 + c0, v1 + c1, v2 + c2
    # the contact (tissue.contact_force)
    Ph = P[33:]
    fc0, fc1, fc2, depth, n0, n1, n2, spring, depth_rate, t0, t1, t2, speed = _contact(
        Ph, p0, p1, p2, vt0, vt1, vt2, inp[9], inp[10]
    )
    ft0, ft1, ft2 = fc0 + inp[6], fc1 + inp[7], fc2 + inp[8]
    # the grip: -K_r θ - D_r ω + r_CH × m g, θ = log(R R_BS0ᵀ)
    gripped = inp[11] > 0.5
    tg0 = tg1 = tg2 = 0.0
    if gripped:
        A = np.empty(9)
        for i in range(3):
            for j in range(3):
                A[3 * i + j] = (
                    R[3 * i] * P[10 + 3 * j]
                    + R[3 * i + 1] * P[11 + 3 * j]
                    + R[3 * i + 2] * P[12 + 3 * j]
                )
        a0, a1, a2 = 0.5 * (A[7] - A[5]), 0.5 * (A[2] - A[6]), 0.5 * (A[3] - A[1])
        s = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if s >= 1e-12:
            scale = np.arctan2(s, 0.5 * (A[0] + A[4] + A[8] - 1.0)) / s
            a0, a1, a2 = scale * a0, scale * a1, scale * a2
        m0, m1, m2 = _cross(rh0, rh1, rh2, P[19], P[20], P[21])
        Kr, Dr = P[22], P[23]
        tg0 = -Kr * a0 - Dr * w0 + m0
        tg1 = -Kr * a1 - Dr * w1 + m1
        tg2 = -Kr * a2 - Dr * w2 + m2
    # I_B = R I_S Rᵀ and I_B ω
    I_B = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            I_B[i, j] = (
                R[3 * i] * P[1] * R[3 * j]
                + R[3 * i + 1] * P[2] * R[3 * j + 1]
                + R[3 * i + 2] * P[3] * R[3 * j + 2]
            )
    iw0 = I_B[0, 0] * w0 + I_B[0, 1] * w1 + I_B[0, 2] * w2
    iw1 = I_B[1, 0] * w0 + I_B[1, 1] * w1 + I_B[1, 2] * w2
    iw2 = I_B[2, 0] * w0 + I_B[2, 1] * w1 + I_B[2, 2] * w2
    F = inp[0:3]
    f[0] = F[0] + ft0 + P[19]
    f[1] = F[1] + ft1 + P[20]
    f[2] = F[2] + ft2 + P[21]
    h0, h1, h2 = _cross(rh0, rh1, rh2, F[0], F[1], F[2])
    q0, q1, q2 = _cross(rt0, rt1, rt2, ft0, ft1, ft2)
    y0, y1, y2 = _cross(w0, w1, w2, iw0, iw1, iw2)
    f[3] = inp[3] + tg0 + h0 + q0 - y0
    f[4] = inp[4] + tg1 + h1 + q1 - y1
    f[5] = inp[5] + tg2 + h2 + q2 - y2
    # the outputs
    out[0], out[1], out[2] = p0, p1, p2
    for i in range(3):
        for j in range(3):
            out[3 + 3 * i + j] = (
                R[3 * i] * P[24 + j] + R[3 * i + 1] * P[27 + j] + R[3 * i + 2] * P[30 + j]
            )
    out[12], out[13], out[14] = vt0, vt1, vt2
    out[15], out[16], out[17] = w0, w1, w2
    out[18], out[19], out[20] = fc0, fc1, fc2
    out[21] = depth if np.isfinite(depth) else -1.0
    out[22], out[23], out[24] = tg0, tg1, tg2
    if not jac:
        return
    M[3:, 3:] = I_B
    C[:, :] = 0.0
    K[:, :] = 0.0
    if depth > 0.0:
        k, e, c = Ph[13], Ph[14], Ph[15]
        F_n = spring * (1.0 + 1.5 * c * depth_rate)
        if F_n > 0.0:
            nv = np.array([n0, n1, n2])
            CT = np.empty((3, 3))
            KT = np.empty((3, 3))
            kn = e * k * depth ** (e - 1.0) * (1.0 + 1.5 * c * depth_rate)
            cn = 1.5 * c * spring
            for i in range(3):
                for j in range(3):
                    nn = nv[i] * nv[j]
                    CT[i, j] = cn * nn
                    KT[i, j] = kn * nn
            # the friction's linearisation across the normal
            mu_F, v_s, b = Ph[16] * F_n, Ph[18], Ph[17]
            if speed > 1e-9 * v_s:
                th = np.tanh(speed / v_s)
                gf = mu_F * th / speed + b
                sgp = mu_F * ((1.0 - th * th) / v_s - th / speed)
                tv = np.array([t0 / speed, t1 / speed, t2 / speed])
                for i in range(3):
                    for j in range(3):
                        proj = (1.0 if i == j else 0.0) - nv[i] * nv[j]
                        CT[i, j] = CT[i, j] + gf * proj + sgp * tv[i] * tv[j]
            else:
                gf = mu_F / v_s + b
                for i in range(3):
                    for j in range(3):
                        proj = (1.0 if i == j else 0.0) - nv[i] * nv[j]
                        CT[i, j] = CT[i, j] + gf * proj
            # v_T = J u, J = [I, -[r_CT]×]: C = Jᵀ C_T J, K = Jᵀ K_T J
            J = np.zeros((3, 6))
            J[0, 0] = J[1, 1] = J[2, 2] = 1.0
            J[0, 4], J[0, 5] = rt2, -rt1
            J[1, 3], J[1, 5] = -rt2, rt0
            J[2, 3], J[2, 4] = rt1, -rt0
            for T, G in ((CT, C), (KT, K)):
                TJ = np.empty((3, 6))
                for i in range(3):
                    for j in range(6):
                        TJ[i, j] = T[i, 0] * J[0, j] + T[i, 1] * J[1, j] + T[i, 2] * J[2, j]
                for i in range(6):
                    for j in range(6):
                        G[i, j] = J[0, i] * TJ[0, j] + J[1, i] * TJ[1, j] + J[2, i] * TJ[2, j]
    if gripped:
        for i in range(3, 6):
            C[i, i] += P[23]
            K[i, i] += P[22]


@njit(cache=True, nogil=True)
def _freehand_step(P, x, inp, n, h, out):  # pragma: no cover - compiled
    """`FreehandProbe.step`'s n linearly implicit Euler substeps of h on the state x (in place),
    then the outputs into `out`: (M + h C + h² K) u₁ = (M + h C) u₀ + h f, x₁ = x₀ + h u₁ with
    R₁ = exp(h [ω₁]×) R₀ made orthonormal by one Newton step."""
    f = np.empty(6)
    M = np.zeros((6, 6))
    M[0, 0] = M[1, 1] = M[2, 2] = P[0]
    C = np.empty((6, 6))
    K = np.empty((6, 6))
    A = np.empty((6, 6))
    rhs = np.empty(6)
    E = np.empty((3, 3))
    Rn = np.empty((3, 3))
    hh = h * h
    for _ in range(n):
        _freehand_forces(P, x, inp, out, f, M, C, K, True)
        for i in range(6):
            total = 0.0
            for j in range(6):
                mc = M[i, j] + h * C[i, j]
                A[i, j] = mc + hh * K[i, j]
                total += mc * x[12 + j]
            rhs[i] = total + h * f[i]
        u = _solve(A, rhs)
        for i in range(6):
            x[12 + i] = u[i]
        for i in range(3):
            x[i] = x[i] + h * u[i]
        # exp(h ω) (Rodrigues) times R, then R (3 I - Rᵀ R) / 2
        rx, ry, rz = h * u[3], h * u[4], h * u[5]
        theta2 = rx * rx + ry * ry + rz * rz
        if theta2 < 1e-12:
            a, b = 1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0
        else:
            theta = np.sqrt(theta2)
            a, b = np.sin(theta) / theta, (1.0 - np.cos(theta)) / theta2
        Sk = np.array([[0.0, -rz, ry], [rz, 0.0, -rx], [-ry, rx, 0.0]])
        for i in range(3):
            for j in range(3):
                sk2 = Sk[i, 0] * Sk[0, j] + Sk[i, 1] * Sk[1, j] + Sk[i, 2] * Sk[2, j]
                E[i, j] = (1.0 if i == j else 0.0) + a * Sk[i, j] + b * sk2
        for i in range(3):
            for j in range(3):
                Rn[i, j] = E[i, 0] * x[3 + j] + E[i, 1] * x[6 + j] + E[i, 2] * x[9 + j]
        for i in range(3):
            for j in range(3):
                RtR = Rn[0, i] * Rn[0, j] + Rn[1, i] * Rn[1, j] + Rn[2, i] * Rn[2, j]
                E[i, j] = (1.5 if i == j else 0.0) - 0.5 * RtR
        for i in range(3):
            for j in range(3):
                x[3 + 3 * i + j] = Rn[i, 0] * E[0, j] + Rn[i, 1] * E[1, j] + Rn[i, 2] * E[2, j]
    _freehand_forces(P, x, inp, out, f, M, C, K, False)


def freehand_step(
    constants: np.ndarray, state: np.ndarray, inputs: np.ndarray, n: int, h: float
) -> np.ndarray:
    """`_freehand_step` into a new output array (25 values; the state advanced in place)."""
    out = np.empty(25)
    _freehand_step(constants, state, inputs, n, h, out)
    return out


# --- an FT-150 packet (sensors.FT150Sensor._measure) ---------------------------------------------


@njit(types.void(_IN, _IN, _IN, _IN, types.float64, _IN, _OUT, _OUT), cache=True, nogil=True)
def _ft_packet(z, scale, true, offset, root_dt, quantum, drift, out):  # pragma: no cover
    """A drifting, quantised packet from 12 standard normal draws z: drift += (z ⊙ s)[:6] √Δt
    (in place), out = q ⊙ rint((true + offset + drift + (z ⊙ s)[6:]) / q), in numpy's order of
    operations, so that the packet is the pure one to the bit."""
    for i in range(6):
        d = drift[i] + z[i] * scale[i] * root_dt
        drift[i] = d
        value = true[i] + offset[i] + d + z[6 + i] * scale[6 + i]
        out[i] = np.rint(value / quantum[i]) * quantum[i]


def ft_packet(
    z: np.ndarray,
    scale: np.ndarray,
    true: np.ndarray,
    offset: np.ndarray,
    root_dt: float,
    quantum: np.ndarray,
    drift: np.ndarray,
) -> np.ndarray:
    """`_ft_packet` into a new (6,) array; `drift` advanced in place."""
    out = np.empty(6)
    _ft_packet(z, scale, true, offset, root_dt, quantum, drift, out)
    return out
