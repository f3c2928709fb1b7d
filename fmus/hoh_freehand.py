"""FMU entry script: the freehand probe (`plant_models.freehand.FreehandProbe`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.freehand import FreehandParams, FreehandProbe

pin_namespace(globals())


class HohFreehand(Fmi2Slave):
    block = FreehandProbe
    params = FreehandParams
