"""The simulated world as pure blocks: arm, tool, tissue, operator and sensor models.

Blocks here may use `hoh_cosim.control`'s math helpers; `hoh_cosim.control` never imports from here.
"""
