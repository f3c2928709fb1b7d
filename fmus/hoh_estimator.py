"""FMU entry script: the estimator block (`hoh_cosim.control.estimator.Estimator`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace

pin_namespace(globals())


class HohEstimator(Fmi2Slave):
    block = Estimator
    params = EstimatorParams
