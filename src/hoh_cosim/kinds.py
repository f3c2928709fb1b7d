"""The kinds of component a scenario can use: which block, which parameters, which FMU."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hoh_cosim.control.block import make_block, takes_rng
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.impedance import (
    CartesianImpedance,
    ImpedanceParams,
    PositionImpedance,
    PositionImpedanceParams,
)
from hoh_cosim.control.sequencer import PoseSequencer, SequencerParams
from plant_models.breathing import Breathing, BreathingParams
from plant_models.freehand import FreehandParams, FreehandProbe
from plant_models.loadcell import LoadCellParams, LoadCellSensor
from plant_models.operator import Operator, OperatorParams
from plant_models.panda import PandaParams, PandaPlant
from plant_models.plant import Plant, PlantParams
from plant_models.sensors import FSE103Params, FSE103Sensor, FT150Params, FT150Sensor

__all__ = ["KINDS", "ComponentKind", "input_starts", "make_block"]


@dataclass(frozen=True)
class ComponentKind:
    name: str
    block: type
    params: type
    fmu_script: str  # the entry script's module name in fmus/ (unique across FMUs)
    description: str
    # the kind whose initial outputs (default parameters) give this one's input start values, port
    # by port where the names and sizes agree: an FMU run alone sees a physically valid world
    starts_from: str | None = None
    # what its FMU's host must have installed (distributions; versions from the project's own
    # requirements): numpy everywhere; scipy for the rotations (`control.frames`: scipy's
    # Rotation, which the frames are checked against), the filters' design (scipy.signal) and the
    # hold's Riccati solution (scipy.linalg). numba and pinocchio are used where installed, never
    # needed: the pure path and the kernels' own UR5 geometry (hoh_cosim.control.jit)
    requires: tuple[str, ...] = ("numpy", "scipy")

    @property
    def random(self) -> bool:
        """Whether the block draws random numbers (takes a generator, so a seed)."""
        return takes_rng(self.block)


KINDS: dict[str, ComponentKind] = {
    k.name: k
    for k in (
        ComponentKind(
            "operator",
            Operator,
            OperatorParams,
            "hoh_operator",
            "the sonographer's hand: a delayed impedance driving a task",
            starts_from="plant",
            requires=("numpy",),
        ),
        ComponentKind(
            "plant", Plant, PlantParams, "hoh_plant", "UR5 under speedL, probe housing and phantom"
        ),
        ComponentKind(
            "ft150",
            FT150Sensor,
            FT150Params,
            "hoh_ft150",
            "Robotiq FT-150 wrist force/torque sensor",
        ),
        ComponentKind(
            "fse103",
            FSE103Sensor,
            FSE103Params,
            "hoh_fse103",
            "Variense FSE103 probe force sensor in its housing",
        ),
        ComponentKind(
            "loadcell",
            LoadCellSensor,
            LoadCellParams,
            "hoh_loadcell",
            "Honeywell Model 31 probe load cell, INA125P and a 10-bit ADC (1 axis)",
        ),
        ComponentKind(
            "estimator",
            Estimator,
            EstimatorParams,
            "hoh_estimator",
            "rebias, gravity compensation, Kalman filters, alignment",
            starts_from="plant",
        ),
        ComponentKind(
            "controller",
            HandGuidingController,
            ControllerParams,
            "hoh_controller",
            "admittance, contact compensation, fixture, limits",
            starts_from="plant",
        ),
        ComponentKind(
            "sequencer",
            PoseSequencer,
            SequencerParams,
            "hoh_sequencer",
            "the gravity-calibration drive through static poses",
            starts_from="plant",
        ),
        ComponentKind(
            "panda",
            PandaPlant,
            PandaParams,
            "hoh_panda",
            "torque-controlled Franka Panda, probe and phantom (seed 001)",
            # its forward dynamics are pinocchio's (ABA): no own implementation to fall back on
            requires=("numpy", "pin"),
        ),
        ComponentKind(
            "impedance",
            CartesianImpedance,
            ImpedanceParams,
            "hoh_impedance",
            "Cartesian impedance for a torque-controlled arm (seed 001, eq. 3-15)",
            starts_from="panda",
        ),
        ComponentKind(
            "ur5_impedance",
            PositionImpedance,
            PositionImpedanceParams,
            "hoh_ur5_impedance",
            "position-based impedance for the speedL-commanded UR5",
            starts_from="plant",
        ),
        ComponentKind(
            "breathing",
            Breathing,
            BreathingParams,
            "hoh_breathing",
            "the patient's breathing: the phantom's surface along its normal",
            requires=("numpy",),
        ),
        ComponentKind(
            "freehand",
            FreehandProbe,
            FreehandParams,
            "hoh_freehand",
            "the probe held by the hand alone, on the phantom (no robot)",
        ),
    )
}


def input_starts(kind: str) -> dict[str, np.ndarray]:
    """Start values of the inputs of `kind` that differ from zero: its `starts_from` kind's initial
    outputs at default parameters, where a port's name and size agree; a rotation (a 9-element
    port named R_...) that nothing gives starts as the identity."""
    spec = KINDS[kind]
    given: dict[str, np.ndarray] = {}
    if spec.starts_from is not None:
        source = KINDS[spec.starts_from]
        block = make_block(source.block, source.params(), 0)
        given = {k: np.asarray(v, dtype=float) for k, v in block.initial_outputs().items()}
    starts: dict[str, np.ndarray] = {}
    for port in spec.block.inputs:
        value = given.get(port.name)
        if value is not None and value.size == port.size:
            starts[port.name] = value.reshape(port.size).copy()
        elif port.size == 9 and port.name.startswith("R_"):
            starts[port.name] = np.eye(3).reshape(9)
    return {name: value for name, value in starts.items() if np.any(value != 0.0)}
