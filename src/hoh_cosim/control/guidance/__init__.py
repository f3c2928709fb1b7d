"""The hand-guiding controller as a mode machine over stages: the modes and their one transition
table (`modes`), the detectors that tell the events (`detectors`), the tick's inputs and the command
the stages refine (`tick`), and one file per stage (`stages`). The controller block that runs them
is `hoh_cosim.control.controller.HandGuidingController`."""
