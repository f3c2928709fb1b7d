"""FMU entry script: the loadcell block (`plant_models.loadcell.LoadCellSensor`) through the generic adapter."""

# First what the host must have (resources/requirements.txt): a host that lacks it gets one line
# naming it and the pip install that fixes it, and the FMU fails to instantiate.
try:
    from hoh_cosim.fmi.host import require
except ImportError:  # the project's code travels in the FMU's resources/: it is not there
    _LINE = "HohLoadCell: resources/hoh_cosim is missing: rebuild the FMU with hoh-cosim export"
    print(_LINE, file=__import__("sys").stderr)
    raise ImportError(_LINE) from None
require(__file__, "HohLoadCell")

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace
from plant_models.loadcell import LoadCellParams, LoadCellSensor

pin_namespace(globals())


class HohLoadCell(Fmi2Slave):
    block = LoadCellSensor
    params = LoadCellParams
