"""FMU entry script: the sequencer block (`hoh_cosim.control.sequencer.PoseSequencer`) through the generic adapter."""

# pythonfmu's wrapper looks for the text "class X(Fmi2Slave):" in this file, so the adapter is
# imported under that name; pin_namespace works around its release of this module's namespace.
from hoh_cosim.control.sequencer import PoseSequencer, SequencerParams
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace

pin_namespace(globals())


class HohSequencer(Fmi2Slave):
    block = PoseSequencer
    params = SequencerParams
