"""The simulated world: arm, tool, tissue, operator and sensor models, and device emulators.

Blocks here may use `hoh_cosim.control`'s math helpers; `hoh_cosim.control` never imports from here.
"""
