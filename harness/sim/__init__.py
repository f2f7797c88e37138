"""Simulation: the vectorized simulator and runs of the FMU through fmpy."""
