"""FMU entry script: the position-based impedance for the UR5 (`PositionImpedance`)."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.control.impedance import PositionImpedance, PositionImpedanceParams
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace

pin_namespace(globals())


class HohUr5Impedance(Fmi2Slave):
    block = PositionImpedance
    params = PositionImpedanceParams
