"""Co-simulation: scenarios, the fmpy master, the in-process engine, recorder, metrics and plots."""
