"""Studies over many runs: sweeps on Dask, linear analysis, tuning, and the verification report."""
