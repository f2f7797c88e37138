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
``estimator``       extended Kalman filter on the compiled model from x and I readings (every state, and the
                    input disturbances of the offset-free MPC)
``closedloop``      fmpy master loop: the actuator FMU as plant, the controller FMU or the MPC (on the exact
                    state or on the estimator, with a measurement delay); stroke profiles; tracking metrics
``study``           the closed-loop study (clean plant, hidden effect: paper model vs extended model)
``robustness``      the offset-free MPC on the estimator on plants that differ from its model
==================  ===================================================================================

Units: SI (s, V, A, m).
"""
