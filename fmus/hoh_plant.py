"""FMU entry script: the plant block (`plant_models.plant.Plant`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.plant import Plant, PlantParams

pin_namespace(globals())


class HohPlant(Fmi2Slave):
    block = Plant
    params = PlantParams
