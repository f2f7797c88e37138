"""Closed-loop control of the actuator on the project's own physics (``fmu_src``; no second copy of the
equations).

==================  ===================================================================================
``opmap``           operating map: steady displacement against voltage and gap, the pull-in boundary, the
                    static inverse (voltage that holds a displacement) and where it exists
                    (``fmu_src.statics``)
``linearize``       linearization at an operating point as a python-control ``StateSpace`` (finite
                    differences of the compiled right-hand side the FMU integrates)
``tuning``          PI(D) gains from the linearization (crossover and phase margin)
``mpc``             nonlinear MPC: shooting over the FMU's compiled integrator (``fmu_src.integrator``)
``closedloop``      fmpy master loop: the actuator FMU as plant, the controller FMU or the MPC; stroke
                    profiles; tracking metrics
``study``           the closed-loop study (clean plant, hidden effect: paper model vs extended model)
==================  ===================================================================================

Units: SI (s, V, A, m).
"""
