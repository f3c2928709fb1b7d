"""The controller core that runs everywhere: in the FMUs, in-process and on the real robot.

Pure math over numpy arrays plus two blocks, `Estimator` and `HandGuidingController`. Nothing here
imports the plant, reads a clock, sleeps or does I/O.
"""
