"""FMU entry script: the fse103 block (`plant_models.sensors.FSE103Sensor`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.sensors import FSE103Params, FSE103Sensor

pin_namespace(globals())


class HohFSE103(Fmi2Slave):
    block = FSE103Sensor
    params = FSE103Params
