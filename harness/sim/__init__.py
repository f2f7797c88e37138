"""Simulation: the vectorized simulator and runs of the FMU through fmpy.

The vectorized simulator (one package, the FMU's contact semantics, the physics from ``fmu_src``):

==========================  ==========================================================================
``simulator``               ``simulate(Runs, Schedule) -> SimResult``: batches of runs with every effect
                            (diagnosis; later control, design sweeps, uncertainty); per-run parameters,
                            blocked mode, constant / zero-order-hold / linear voltage inputs, per-run
                            sample periods (``simulate_by_period``)
``population``              ``prepare_test``, ``integrate(tests, which, C, m, PopulationSettings) ->
                            BatchResult``: a whole NSGA-II population of (C, m) on T3/T5 of several
                            samples (identification), run on the same core: the current prescribed by the
                            exact zero-order-hold RL solution (``zoh_current``), the equilibrium settle test
                            and closed-form linear tails
``core``                    the compiled stepping core (numba): RK4 steps of every run through a part of
                            the schedule, contact events, exact sensor lag, settle tests; its right-hand
                            side, force and contact force are ``fmu_src.effects``' functions as the FMU's
                            integrator compiles them (``fmu_src.integrator.COMPILED_PHYSICS``); its state
                            layout (``Y_STATES``) follows ``fmu_src.specs``
``physics``                 per-run constants and parameter blocks of the core, step-size rules (every
                            parameter, switch, state position and time constant from ``fmu_src.specs``)
``contact``                 event location (impact, release; numba-callable)
``kernels``                 cached force kernels, stacked tables
``settings``, ``results``   frozen settings (``MechParams``, ``PopulationSettings``, ``Schedule``),
                            ``SimInputError``; ``SimResult``, ``BatchResult``
``fmurun``, ``replay``      the FMU through fmpy; the rig's test protocol replayed on it
==========================  ==========================================================================
"""
