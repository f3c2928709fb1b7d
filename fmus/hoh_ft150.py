"""FMU entry script: the ft150 block (`plant_models.sensors.FT150Sensor`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.sensors import FT150Params, FT150Sensor

pin_namespace(globals())


class HohFT150(Fmi2Slave):
    block = FT150Sensor
    params = FT150Params
