"""Co-simulation: scenarios, the fmpy master, the in-process engine, recorder, metrics and plots.

The engines and couplings are closed sets defined here, where importing them costs nothing (the
command line offers them as choices before it imports any engine).
"""

__all__ = ["COUPLINGS", "ENGINES", "ENGINE_COUPLING", "EXTERNAL_ENGINES"]

# engines that run our FMUs in another tool (`hoh_cosim.cosim.external`)
EXTERNAL_ENGINES = ("libcosim", "ecos")
ENGINES = ("fmu", "inprocess", *EXTERNAL_ENGINES)
# how an output reaches the inputs it is connected to (see `hoh_cosim.cosim.external`):
# gauss-seidel: at once, in the file's order; jacobi: when the source's step ends (libcosim);
# jacobi-eager: one tick after the source's step began, even if that step lasts several (ecos)
COUPLINGS = ("gauss-seidel", "jacobi", "jacobi-eager")
# our master's coupling that each external engine has
ENGINE_COUPLING = {"libcosim": "jacobi", "ecos": "jacobi-eager"}
