"""FMU entry script: seed 001's Cartesian impedance controller (`CartesianImpedance`)."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.control.impedance import CartesianImpedance, ImpedanceParams
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace

pin_namespace(globals())


class HohImpedance(Fmi2Slave):
    block = CartesianImpedance
    params = ImpedanceParams
