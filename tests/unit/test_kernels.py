"""The compiled kernels against their pure references: the Kalman bank, the estimator, the UR5's
kinematics (pinocchio) and the plant, within 1e-12 relative on varied and recorded inputs."""

from __future__ import annotations

import copy
import dataclasses
import importlib
import io
import math
import pickle
import types

import numpy as np
import pytest

from hoh_cosim.control import kernels
from hoh_cosim.control.admittance import TRANSLATION_GAINS, AdmittanceGains, deadband_linear
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.gravity import ToolParams
from hoh_cosim.control.kalman import KalmanBank, KalmanParams
from hoh_cosim.control.kernels import KernelKalmanBank, kernels_enabled, use_kernels
from hoh_cosim.control.passivity import PassivityParams
from hoh_cosim.control.probe_correction import ProbeCorrectionParams
from hoh_cosim.control.release import ReleaseParams
from hoh_cosim.control.supervisor import Status
from hoh_cosim.control.variable_admittance import VariableAdmittance, VariableAdmittanceParams
from hoh_cosim.errors import ConfigError
from plant_models.freehand import FreehandParams, FreehandProbe
from plant_models.kernels import KINEMATICS_LAYOUT, KernelUR5
from plant_models.plant import Plant, PlantParams
from plant_models.sensors import FT150Params, FT150Sensor
from plant_models.tissue import PhantomParams
from plant_models.tool import CableDrag, ToolModel
from plant_models.ur5 import FramePlacement
from tests.estimates import controller_inputs
from tests.streams import SensorStream

REL = 1e-12


class Agreement:
    """The largest |a - b| / scale over a run, per signal, with each signal's scale its largest
    |value| in the reference over the run (at least `floor`): relative agreement of whole signals,
    which a value crossing zero does not make meaningless."""

    def __init__(self, floor: float = 1e-9) -> None:
        self.floor = floor
        self.diff: dict[str, float] = {}
        self.scale: dict[str, float] = {}

    def add(self, name: str, reference: np.ndarray, other: np.ndarray) -> None:
        reference, other = np.asarray(reference, float), np.asarray(other, float)
        same_nan = np.isnan(reference) & np.isnan(other)
        diff = np.where(same_nan, 0.0, np.abs(reference - other))
        finite = np.where(np.isfinite(reference), np.abs(reference), 0.0)
        self.diff[name] = max(self.diff.get(name, 0.0), float(np.max(diff, initial=0.0)))
        self.scale[name] = max(self.scale.get(name, self.floor), float(np.max(finite, initial=0.0)))

    def worst(self) -> tuple[str, float]:
        name = max(self.diff, key=lambda k: self.diff[k] / self.scale[k])
        return name, self.diff[name] / self.scale[name]


def _pure_and_compiled(make):
    with use_kernels(False):
        pure = make()
    with use_kernels(True):
        compiled = make()
    return pure, compiled


def test_the_switch_reads_the_environment_and_names_a_bad_value(monkeypatch):
    monkeypatch.setattr(kernels, "_enabled", None)
    monkeypatch.setenv("HOH_COSIM_KERNELS", "pure")
    assert not kernels_enabled()
    monkeypatch.setattr(kernels, "_enabled", None)
    monkeypatch.setenv("HOH_COSIM_KERNELS", "fast")
    with pytest.raises(ConfigError, match=r"HOH_COSIM_KERNELS: expected one of compiled, pure, "):
        kernels_enabled()
    monkeypatch.setattr(kernels, "_enabled", None)
    monkeypatch.delenv("HOH_COSIM_KERNELS")
    assert kernels_enabled()


def test_blocks_take_the_path_the_switch_says():
    pure, compiled = _pure_and_compiled(Estimator)
    assert isinstance(pure._filters, KalmanBank)
    assert isinstance(compiled._filters, KernelKalmanBank)
    pure, compiled = _pure_and_compiled(Plant)
    assert pure._kernel is None
    assert isinstance(compiled._kernel, KernelUR5)


@pytest.mark.parametrize("dt", [1e-3, 2e-3, 8e-3])
def test_kalman_bank_matches_the_pure_bank(dt):
    rng = np.random.default_rng(3)
    channels = [
        KalmanParams(q=rng.uniform(1, 1e4, 3), r=rng.uniform(1e-3, 1.0, 3)) for _ in range(3)
    ]
    pure, compiled = KalmanBank(channels), KernelKalmanBank(channels)
    # readings on one run of channels at a time: none, the first two (a wrist packet), the last
    # (a probe packet), all three
    patterns = [(False, False, False), (True, True, False), (False, False, True), (True,) * 3]
    agree = Agreement()
    for k in range(3000):
        pattern = patterns[rng.integers(4)] if k % 3 == 0 else patterns[0]
        z = [rng.normal(5.0, 2.0, 3) if on else None for on in pattern]
        agree.add("forces", pure.step_bank(dt, z), compiled.step_bank(dt, z))
        agree.add("x", pure.x, compiled.x)
        if k % 97 == 0:
            agree.add("P", pure.P, compiled.P)
        if k == 1500:
            pure.reset()
            compiled.reset()
    name, worst = agree.worst()
    assert worst < REL, f"{name}: {worst:.3g}"
    compiled.step_bank(dt, (np.ones(3), None, None))  # after a correction, symmetric to the bit
    np.testing.assert_array_equal(compiled.P, np.swapaxes(compiled.P, 1, 2))


def test_the_compiled_bank_refuses_readings_that_are_not_one_run_of_channels():
    bank = KernelKalmanBank([KalmanParams(q=[1.0] * 3, r=[1.0] * 3)] * 3)
    with pytest.raises(ConfigError, match=r"one run of channels at a time, got readings on .*0, 2"):
        bank.step_bank(1e-3, (np.zeros(3), None, np.zeros(3)))


def _stream(seed: int) -> SensorStream:
    return SensorStream(
        R_BS=lambda t: (
            rotvec_to_matrix([0.3 * math.sin(t), -0.2 * math.cos(0.7 * t), 0.1 * t])
            @ rotvec_to_matrix([math.pi, 0.0, 0.0])
        ),
        hand_B=lambda t: np.array([4.0 * math.sin(2 * t), 3.0 * math.cos(1.3 * t), -1.0]),
        hand_torque_B=lambda t: np.array([0.1 * math.sin(t), 0.05, -0.2 * math.cos(3 * t)]),
        contact_B=lambda t: np.array([0.0, 0.5 * math.sin(t), 6.0 + 2.0 * math.sin(0.5 * t)]),
        ft_sigma=np.array([0.3, 0.3, 0.1, 0.01, 0.01, 0.01]),
        probe_sigma=np.array([0.05, 0.05, 0.05]),
        seed=seed,
    )


CONFIGURATIONS = {
    "default": {},
    "no_probe": {"use_probe": False},
    "lever_and_probe_mass": {"p_SR_S": [0.01, -0.02, -0.09], "probe_mass_kg": 0.05},
    "probe_check_online": {
        "probe_correction": ProbeCorrectionParams(kind="online", check_s=0.3),
        "tool": ToolParams(0.5, [-0.01, 0.0, -0.07]),
    },
    "butterworth": {"filter": "butterworth"},
    "one_euro": {"filter": "one_euro"},
    "lead_lowpass": {"filter": "lead_lowpass"},
    "given_bias": {
        "ft_rebias_packets": 0,
        "probe_rebias_packets": 0,
        "ft_bias": [1.0, -2.0, 0.5, 0.02, -0.01, 0.03],
        "probe_bias": [0.3, 0.1, -0.2],
    },
}


@pytest.mark.parametrize("dt", [1e-3, 2e-3])
@pytest.mark.parametrize("config", sorted(CONFIGURATIONS))
def test_estimator_matches_the_pure_estimator(config, dt):
    """Both paths on the same packets: noise, a tool that turns, NaN packets, a new rebias, a
    reset, and copies (pickle, deepcopy: an FMU's state) that carry on in place of the originals."""
    params = EstimatorParams(
        **{"ft_rebias_packets": 20, "probe_rebias_packets": 10, **CONFIGURATIONS[config]}
    )
    pure, compiled = _pure_and_compiled(lambda: Estimator(params))
    if params.filter == "kalman":
        assert compiled._kernel
    else:
        assert type(compiled._filters).__name__.startswith("Kernel")
    stream = _stream(seed=7)
    stream.dt = dt
    agree = Agreement()
    n = round(4.0 / dt)
    for k, (t, inputs) in enumerate(stream.ticks(n)):
        if k in (n // 5, n // 5 + 3):  # a NaN in a wrist packet, then in a probe packet
            inputs["wrench_S"][2] = math.nan
            inputs["force_P"][0] = math.nan
        if k == n // 3:
            pure.start_rebias()
            compiled.start_rebias()
        if k == n // 2:
            pure, compiled = pickle.loads(pickle.dumps(pure)), pickle.loads(pickle.dumps(compiled))
        if k == 2 * n // 3:
            pure, compiled = copy.deepcopy(pure), copy.deepcopy(compiled)
        if k == 5 * n // 6:
            pure.reset()
            compiled.reset()
        a, b = pure.step(t, dt, inputs), compiled.step(t, dt, inputs)
        assert a.keys() == b.keys()
        for name in a:
            agree.add(name, a[name], b[name])
    name, worst = agree.worst()
    assert worst < REL, f"{config}, {name}: {worst:.3g}"
    # the run did what it is meant to exercise
    assert compiled.rejected_packets == 0  # counted since the reset
    assert agree.scale["F_hand_B"] > 1.0
    if params.use_probe:
        assert agree.scale["rejected_packets"] >= 2.0
        assert agree.scale["F_probe_B"] > 1.0
        assert agree.scale["probe_mismatch"] > 0.0


def test_a_wrong_kernel_would_be_caught():
    """The agreement test can fail: a compiled estimator whose probe sensor is mounted otherwise
    (R_SP turned by 1e-9 rad) is told apart from the pure one."""
    params = EstimatorParams(ft_rebias_packets=20, probe_rebias_packets=10)
    pure, compiled = _pure_and_compiled(lambda: Estimator(params))
    compiled._filters.set_rotation(rotvec_to_matrix([1e-9, 0.0, 0.0]) @ params.R_SP)
    agree = Agreement()
    for t, inputs in _stream(seed=1).ticks(1500):
        a, b = pure.step(t, 1e-3, inputs), compiled.step(t, 1e-3, inputs)
        agree.add("F_probe_B", a["F_probe_B"], b["F_probe_B"])
    assert agree.worst()[1] > 100 * REL


class _ByName(pickle.Pickler):
    """As an FMU's state is pickled (hoh_cosim.fmi.slave): a module (pinocchio) by its name."""

    def persistent_id(self, obj):
        return obj.__name__ if isinstance(obj, types.ModuleType) else None


class _Import(pickle.Unpickler):
    def persistent_load(self, pid):
        return importlib.import_module(pid)


def _copy_as_fmu_state(block):
    buffer = io.BytesIO()
    _ByName(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(block)
    return _Import(io.BytesIO(buffer.getvalue())).load()


def _frames_model():
    return Plant().model  # the UR5 with the default tool's frames (pinocchio)


def test_ur5_kinematics_match_pinocchio():
    model = _frames_model()
    kernel = KernelUR5(model)
    rng = np.random.default_rng(11)
    entries = [3, 7, 11, 0, 1, 2, 4, 5, 6, 8, 9, 10]  # p, then R row by row
    agree = Agreement(floor=1.0)
    for _ in range(300):
        q, qd, qdd = rng.uniform(-6, 6, 6), rng.uniform(-3, 3, 6), rng.uniform(-20, 20, 6)
        model.update(q, qd, qdd)
        k = kernel.tool_kinematics(q, qd, qdd)
        L = KINEMATICS_LAYOUT
        agree.add("pose_T", model.homogeneous("tcp").take(entries), k[L["pose_T"]])
        agree.add("pose_S", model.homogeneous("ft_sensor").take(entries), k[L["pose_S"]])
        agree.add("twist_T", model.twist("tcp"), k[L["twist_T"]])
        agree.add("accel_C", model.acceleration("tool_com"), k[L["accel_C"]])
        agree.add("accel_P", model.acceleration("probe_sensor")[:3], k[L["accel_P"]])
        for frame in model.frame_ids:
            agree.add(f"J {frame}", model.jacobian(q, frame), kernel.jacobian(q, frame))
    name, worst = agree.worst()
    assert worst < REL, f"{name}: {worst:.3g}"


def test_ur5_kinematics_without_pinocchio_match_pinocchio():
    # the kernels' own geometry of the chain (ur5.chain_geometry: an FMU's host without pinocchio)
    plant = Plant()
    model = plant.model
    frames = tuple(
        FramePlacement(name, p_EX_E, R_EX)
        for name, (p_EX_E, R_EX) in plant.params.tool.flange_frames().items()
    )
    own, reference = KernelUR5(None, frames), KernelUR5(model)
    assert own.frame_ids.keys() == reference.frame_ids.keys()
    np.testing.assert_allclose(own._G, reference._G, rtol=0.0, atol=1e-15)
    rng = np.random.default_rng(12)
    agree = Agreement(floor=1.0)
    for _ in range(100):
        q, qd, qdd = rng.uniform(-6, 6, 6), rng.uniform(-3, 3, 6), rng.uniform(-20, 20, 6)
        model.update(q, qd, qdd)
        agree.add("tool", reference.tool_kinematics(q, qd, qdd), own.tool_kinematics(q, qd, qdd))
        agree.add("J tcp", model.jacobian(q, "tcp"), own.jacobian(q, "tcp"))
    name, worst = agree.worst()
    assert worst < REL, f"{name}: {worst:.3g}"


FREEHAND_PHANTOMS = {
    "plane": PhantomParams(plane_point_B=[0.0, 0.0, 0.245]),
    "ellipsoid": PhantomParams(
        shape="ellipsoid",
        ellipsoid_center_B=[-0.05, -0.45, 0.145],
        ellipsoid_axes=[0.17, 0.25, 0.1],
    ),
    "none": PhantomParams(shape="none"),
}


@pytest.mark.parametrize("shape", ["plane", "ellipsoid"])
def test_plant_matches_the_pinocchio_plant(shape):
    """Both plants under the same commands and loads (a moving arm, a cable, a probe mass, the
    phantom touched as it breathes, commands to rest braked with speedL's larger `a`), and copies
    that carry on in place of the originals."""
    params = PlantParams(
        tool=ToolModel(probe_mass_kg=0.05, cable=CableDrag(enabled=True)),
        phantom=PhantomParams(plane_point_B=[0.0, 0.0, 0.2])  # the tip goes down to 0.153 m
        if shape == "plane"
        else FREEHAND_PHANTOMS["ellipsoid"],
    )
    pure, compiled = _pure_and_compiled(lambda: Plant(params))
    rng = np.random.default_rng(5)
    agree = Agreement()
    command = np.zeros(6)
    for k in range(4000):
        t = k * 1e-3
        brake = 0.0
        if k % 8 == 0:
            command = np.concatenate([rng.normal(0, 0.05, 3), rng.normal(0, 0.2, 3)])
            command[2] = -0.04  # down, into the phantom
        if k % 200 >= 150:  # a release: rest, braked at 10 m/s² (above the arm's own 1.5)
            command, brake = np.zeros(6), 10.0
        inputs = {
            "twist_cmd_B": command,
            "brake_accel": np.array([brake]),
            "F_hand_B": rng.normal(0, 3, 3),
            "tau_hand_B": rng.normal(0, 0.2, 3),
            "F_tip_B": np.zeros(3) if k % 500 < 250 else rng.normal(0, 1, 3),
            "surface_offset_m": np.array([0.01 * math.sin(1.6 * t)]),
            "surface_rate_m_s": np.array([0.016 * math.cos(1.6 * t)]),
        }
        if k == 2000:
            pure, compiled = _copy_as_fmu_state(pure), _copy_as_fmu_state(compiled)
        a, b = pure.step(t, 1e-3, inputs), compiled.step(t, 1e-3, inputs)
        for name in a:
            agree.add(name, a[name], b[name])
    name, worst = agree.worst()
    assert worst < REL, f"{name}: {worst:.3g}"
    assert agree.scale["qd"] > 0.01  # the arm moved
    assert agree.scale["F_contact_B"] > 1.0  # and pressed on the phantom


def _freehand_agreement(params: FreehandParams, *, wrong: float = 0.0) -> Agreement:
    """Both freehand probes under the same hand (pressed in, slid, twisted, let go and gripped
    again), on a breathing surface, with copies that carry on in place of the originals halfway;
    `wrong` makes the compiled probe's phantom that much stiffer, relatively.

    Each step starts the compiled probe from the pure one's state: the step is what is compiled.
    Left to run on its own, the two part by more than 1e-12 within two seconds of this hand's
    stick and slip, and so does the pure probe from itself started one rounding higher (checked:
    at the same steps, by the same factors): the smoothed Coulomb friction's slope (μ F_n / v_s,
    1600 N·s/m at 8 N) amplifies the last bit of a sum taken in another order."""
    pure, compiled = _pure_and_compiled(lambda: FreehandProbe(params))
    if wrong:
        compiled._constants[46] *= 1.0 + wrong  # the phantom's k (kernels.freehand_constants)
    rng = np.random.default_rng(8)
    agree = Agreement()
    force = np.zeros(3)
    for k in range(2000):
        t = k * 2e-3
        if k % 10 == 0:
            force = np.array([*rng.normal(0.0, 2.0, 2), -6.0 + rng.normal(0.0, 2.0)])
        inputs = {
            "F_hand_B": force - params.tool.mass_kg * params.g_B,
            "tau_hand_B": rng.normal(0.0, 0.05, 3),
            "F_tip_B": np.zeros(3) if k % 700 < 500 else rng.normal(0.0, 1.0, 3),
            "surface_offset_m": np.array([0.01 * math.sin(1.6 * t)]),
            "surface_rate_m_s": np.array([0.016 * math.cos(1.6 * t)]),
            "hand_on": np.array([0.0 if 900 <= k < 960 else 1.0]),
        }
        if k == 1000:
            pure, compiled = _copy_as_fmu_state(pure), _copy_as_fmu_state(compiled)
        compiled._x[:] = pure._x
        a, b = pure.step(t, 2e-3, inputs), compiled.step(t, 2e-3, inputs)
        for name in a:
            agree.add(name, a[name], b[name])
    return agree


@pytest.mark.parametrize("shape", sorted(FREEHAND_PHANTOMS))
def test_freehand_probe_matches_the_pure_probe(shape):
    """Every output of every step within 1e-12, on each shape of phantom, in contact and sliding
    (the friction's both branches) and in the air, gripped and let go."""
    agree = _freehand_agreement(FreehandParams(phantom=FREEHAND_PHANTOMS[shape]))
    name, worst = agree.worst()
    assert worst < REL, f"{name}: {worst:.3g}"
    assert agree.scale["twist_B"] > 0.01  # the probe moved
    if shape != "none":
        assert agree.scale["F_contact_B"] > 1.0  # and pressed on the phantom


def test_a_wrong_freehand_kernel_would_be_caught():
    """The agreement test can fail: a compiled probe whose phantom is 1e-9 stiffer is told
    apart."""
    agree = _freehand_agreement(FreehandParams(phantom=FREEHAND_PHANTOMS["plane"]), wrong=1e-9)
    assert agree.worst()[1] > 100 * REL


def test_ft150_packets_are_the_pure_ones_to_the_bit():
    """The compiled packet (drift, noise, quantisation) keeps numpy's order of operations: the
    same draws give the same packets, bit for bit, over a moving wrench, a retune and a copy."""
    pure, compiled = _pure_and_compiled(
        lambda: FT150Sensor(FT150Params(), rng=np.random.default_rng(3))
    )
    assert compiled._compiled
    assert not pure._compiled
    rng = np.random.default_rng(4)
    packets = 0
    for k in range(3000):
        t = k * 1e-3
        true = {"wrench_S_true": rng.normal(0.0, 5.0, 6)}
        if k == 1500:
            pure, compiled = _copy_as_fmu_state(pure), _copy_as_fmu_state(compiled)
            tuned = dataclasses.replace(pure.params, offset=np.full(6, 0.3))
            pure.retune(tuned)
            compiled.retune(tuned)
        a, b = pure.step(t, 1e-3, true), compiled.step(t, 1e-3, true)
        assert np.array_equal(a["wrench_S"], b["wrench_S"]), t
        packets = int(a["counter"][0])
    assert packets > 500
    assert np.array_equal(pure.drift, compiled.drift)
    assert np.any(pure.drift != 0.0)


def test_warm_up_is_idempotent():
    kernels.warm_up("kalman")
    kernels.warm_up()
    kernels.warm_up()
    assert kernels._warm == {"estimator", "one_euro", "butterworth", "lead_lowpass", "laws"}
    # each of the controller's kernels has its one version, and compiles no other
    for dispatcher in (kernels._variable_law, kernels._release_norms, kernels._passivity):
        assert len(dispatcher.signatures) == 1
        assert not dispatcher._can_compile


def test_the_arm_cycles_small_solvers_match_lapack():
    """The compiled cycle's σ_min/σ_max (one-sided Jacobi) and solve (LU, partial pivoting) against
    numpy's LAPACK, on random and nearly singular 6x6 matrices."""
    from plant_models.kernels import _singular_extremes, _solve

    rng = np.random.default_rng(2)
    worst_sigma = worst_solve = 0.0
    for k in range(500):
        J = rng.normal(size=(6, 6))
        if k % 2:  # σ_min from 1e-6 to 0.1 of the others
            U, s, Vt = np.linalg.svd(J)
            s[-1] = 10.0 ** rng.uniform(-6, -1)
            J = U @ np.diag(s) @ Vt
        s = np.linalg.svd(J, compute_uv=False)
        lo, hi = _singular_extremes(J)
        worst_sigma = max(worst_sigma, abs(lo - s[-1]) / s[0], abs(hi - s[0]) / s[0])
        b = rng.normal(size=6)
        x = np.linalg.solve(J, b)
        error = np.max(np.abs(_solve(J, b) - x)) / np.max(np.abs(x))
        worst_solve = max(worst_solve, error / (s[0] / s[-1]))  # relative to the condition
    assert worst_sigma < REL
    assert worst_solve < REL


# --- the controller's new laws (variable law, release detection, passivity) ---------------------


def _guiding(k: int, dt: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A hand that pushes in bursts and lets go (a step to nothing in the raw packet, the estimate
    falling after it), turns the probe, a contact now and then, and a tip that shakes at 2 Hz in
    the second half (the oscillation watch halves the slope)."""
    t = k * dt
    phase = t % 1.6
    pushing = phase < 1.2
    F = np.array([6.0 * math.cos(0.7 * t), 4.0 * math.sin(0.9 * t), 1.5 * math.sin(0.3 * t)])
    if not pushing:
        F = F * math.exp(-(phase - 1.2) / 0.03)
    raw = (F if pushing else np.zeros(3)) + rng.normal(0.0, 0.2, 3)
    shake = 0.004 * math.sin(2 * math.pi * 2.0 * t) if t > 3.0 else 0.0
    return controller_inputs(
        F_hand_B=F,
        F_hand_meas_B=raw,
        tau_hand_B=[0.3 * math.sin(t), -0.2, 0.15 * math.cos(2 * t)],
        F_probe_B=[0.0, 0.0, 2.0 if 2.0 < t < 2.5 else 0.0],
        p_BT_B=[0.3 + 0.02 * math.sin(0.5 * t) + shake, shake, 0.3],
    )


def _read_only_strided(x: np.ndarray) -> np.ndarray:
    spread = np.zeros(2 * x.size)
    spread[::2] = x
    view = spread[::2]
    view.flags.writeable = False
    return view


_NEW_LAWS = ControllerParams(
    translation=AdmittanceGains(law="variable"),
    release=ReleaseParams(enabled=True),
    passivity=PassivityParams(enabled=True, tank_max_J=2e-3),
)


@pytest.mark.parametrize(
    "params",
    [
        _NEW_LAWS,
        # the rotation by another law: the variable law's call leaves ω to apply_law
        ControllerParams(
            translation=AdmittanceGains(law="variable"),
            rotation=AdmittanceGains(law="sigmoid"),
            variable=VariableAdmittanceParams(intent_gain=0.3, oscillation_quiet_s=0.5),
            release=ReleaseParams(enabled=True, horizon_s=0.1),
            passivity=PassivityParams(enabled=True, tank_max_J=1e-3),
        ),
    ],
    ids=["new_laws", "sigmoid_rotation"],
)
@pytest.mark.parametrize("dt", [2e-3, 8e-3])
def test_controller_with_the_new_laws_matches_the_pure_controller(params, dt):
    """Both paths on the same estimates: releases, the watch's halvings, retuning, copies (an
    FMU's state) that carry on, and a reset; every output of every tick within 1e-12."""
    pure, compiled = _pure_and_compiled(lambda: HandGuidingController(params))
    assert type(compiled._variable.law).__name__ == "KernelVariableAdmittance"
    assert type(compiled.release).__name__ == "KernelReleaseDetector"
    assert type(compiled._passivity.controller).__name__ == "KernelPassivityController"
    assert type(pure._variable.law) is VariableAdmittance
    rng = np.random.default_rng(3)
    agree = Agreement()
    n = round(8.0 / dt)
    flags = 0
    stability = 1.0
    for k in range(n):
        if k == n // 4:
            pure, compiled = pickle.loads(pickle.dumps(pure)), pickle.loads(pickle.dumps(compiled))
        if k == n // 2:
            pure, compiled = copy.deepcopy(pure), copy.deepcopy(compiled)
            tuned = dataclasses.replace(
                params,
                translation=dataclasses.replace(
                    params.translation, slope=[0.0145] * 3, deadband=[0.45, 0.45, 0.25]
                ),
            )
            pure.retune(tuned)
            compiled.retune(tuned)
        if k == 7 * n // 8:
            pure.reset()
            compiled.reset()
        inputs = _guiding(k, dt, rng)
        if k % 3 == 0:  # as an engine may hand them over: read-only, strided
            inputs = {name: _read_only_strided(x) for name, x in inputs.items()}
        a, b = pure.step(k * dt, dt, inputs), compiled.step(k * dt, dt, inputs)
        for name in a:
            agree.add(name, a[name], b[name])
        for name in ("factor", "stability", "swings", "oscillation_m_s"):
            agree.add(
                name, getattr(pure._variable.law, name), getattr(compiled._variable.law, name)
            )
        agree.add(
            "energy", pure._passivity.controller.energy_J, compiled._passivity.controller.energy_J
        )
        assert pure.release.phase == compiled.release.phase
        flags |= int(a["status"][0])
        stability = min(stability, pure._variable.law.stability)
    name, worst = agree.worst()
    assert worst < REL, f"{name}: {worst:.3g}"
    # the run did what it is meant to exercise
    assert flags & int(Status.RELEASED)
    assert flags & int(Status.BRAKING)
    assert flags & int(Status.PASSIVITY)
    assert stability <= 0.5
    assert agree.scale["twist_law_B"] > 0.05


def test_the_variable_laws_step_matches_the_pure_law(rng):
    """`step` (slope and deadband given per call, with and without the tip's position)."""
    pure, compiled = _pure_and_compiled(kernels.variable_law)
    assert type(compiled) is kernels.KernelVariableAdmittance
    agree = Agreement()
    slope, eta = TRANSLATION_GAINS.slope, TRANSLATION_GAINS.deadband
    for k in range(500):
        F = rng.normal(scale=4.0, size=3)
        p_B = None if k % 7 == 0 else np.array([0.01 * math.sin(12 * k * 0.008), 0.0, 0.3])
        agree.add(
            "v",
            pure.step(k * 0.008, F, slope, eta, p_B),
            compiled.step(k * 0.008, F, slope, eta, p_B),
        )
    assert agree.worst()[1] < REL


def test_a_wrong_law_kernel_would_be_caught():
    """A compiled variable law whose deadband on x is off by one part in 1e9 is told apart from
    the pure one."""
    pure, compiled = _pure_and_compiled(lambda: HandGuidingController(_NEW_LAWS))
    compiled.step(0.0, 8e-3, controller_inputs())  # the gains are set at the first step
    compiled._variable.law.constants[kernels._V_GAINS + 3] *= 1.0 + 1e-9
    pure.step(0.0, 8e-3, controller_inputs())
    rng = np.random.default_rng(3)
    agree = Agreement()
    for k in range(1, 500):
        inputs = _guiding(k, 8e-3, rng)
        agree.add(
            "twist_B",
            pure.step(k * 8e-3, 8e-3, inputs)["twist_B"],
            compiled.step(k * 8e-3, 8e-3, inputs)["twist_B"],
        )
    assert agree.worst()[1] > 100 * REL


def test_eq_10_on_force_and_torque_at_once_is_the_pure_law_to_the_bit(rng):
    """`deadband_law6` against `admittance.deadband_linear` on [F; τ]: inside and at the deadband,
    zeros of both signs, negative and positive pushes; the same bits, signs of zero included."""
    slope = np.concatenate([TRANSLATION_GAINS.slope, [0.4, 0.4, 0.4]])
    eta = np.concatenate([TRANSLATION_GAINS.deadband, [0.1, 0.1, 0.1]])
    for k in range(2000):
        F, tau = rng.normal(scale=2.0, size=3), rng.normal(scale=0.2, size=3)
        F[k % 3] = (0.0, -0.0, eta[k % 3], -eta[k % 3])[k % 4]
        got = kernels.deadband_law6(F, tau, slope, eta)
        pure = deadband_linear(np.concatenate([F, tau]), slope, eta)
        np.testing.assert_array_equal(got, pure)
        np.testing.assert_array_equal(np.signbit(got), np.signbit(pure))


def test_the_controllers_law_takes_the_compiled_eq_10_and_gives_the_pure_twist():
    pure, compiled = _pure_and_compiled(HandGuidingController)
    assert compiled._request[0]._compiled
    assert not pure._request[0]._compiled
    rng = np.random.default_rng(5)
    for k in range(300):
        inputs = _guiding(k, 8e-3, rng)
        np.testing.assert_array_equal(
            pure.step(k * 8e-3, 8e-3, inputs)["twist_B"],
            compiled.step(k * 8e-3, 8e-3, inputs)["twist_B"],
        )
