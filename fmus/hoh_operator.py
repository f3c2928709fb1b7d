"""FMU entry script: the operator block (`plant_models.operator.Operator`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.operator import Operator, OperatorParams

pin_namespace(globals())


class HohOperator(Fmi2Slave):
    block = Operator
    params = OperatorParams
