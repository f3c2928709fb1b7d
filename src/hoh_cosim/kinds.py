"""The kinds of component a scenario can use: which block, which parameters, which FMU."""

from __future__ import annotations

from dataclasses import dataclass

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
from plant_models.operator import Operator, OperatorParams
from plant_models.panda import PandaParams, PandaPlant
from plant_models.plant import Plant, PlantParams
from plant_models.sensors import FSE103Params, FSE103Sensor, FT150Params, FT150Sensor

__all__ = ["KINDS", "ComponentKind", "make_block"]


@dataclass(frozen=True)
class ComponentKind:
    name: str
    block: type
    params: type
    fmu_script: str  # the entry script's module name in fmus/ (unique across FMUs)
    description: str

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
            "estimator",
            Estimator,
            EstimatorParams,
            "hoh_estimator",
            "rebias, gravity compensation, Kalman filters, alignment",
        ),
        ComponentKind(
            "controller",
            HandGuidingController,
            ControllerParams,
            "hoh_controller",
            "admittance, contact compensation, fixture, limits",
        ),
        ComponentKind(
            "sequencer",
            PoseSequencer,
            SequencerParams,
            "hoh_sequencer",
            "the gravity-calibration drive through static poses",
        ),
        ComponentKind(
            "panda",
            PandaPlant,
            PandaParams,
            "hoh_panda",
            "torque-controlled Franka Panda, probe and phantom (seed 001)",
        ),
        ComponentKind(
            "impedance",
            CartesianImpedance,
            ImpedanceParams,
            "hoh_impedance",
            "Cartesian impedance for a torque-controlled arm (seed 001, eq. 3-15)",
        ),
        ComponentKind(
            "ur5_impedance",
            PositionImpedance,
            PositionImpedanceParams,
            "hoh_ur5_impedance",
            "position-based impedance for the speedL-commanded UR5",
        ),
    )
}
