"""Physics core of the MPC diaphragm actuator (pure numpy/scipy, no I/O).

One implementation, used by the FMU slave (``fmu_src.mpc_actuator``) and by the
harness. All quantities are SI inside this package.
"""
