"""FMU entry script: the Panda plant block (`plant_models.panda.PandaPlant`) through the adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.panda import PandaParams, PandaPlant

pin_namespace(globals())


class HohPanda(Fmi2Slave):
    block = PandaPlant
    params = PandaParams
