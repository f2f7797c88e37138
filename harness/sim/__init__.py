"""Simulation: the vectorized simulator and runs of the FMU through fmpy.

The vectorized simulator (one package, the FMU's contact semantics, the physics from ``fmu_src``):

==========================  ==========================================================================
``simulator``               ``simulate(Runs, Schedule) -> SimResult``: batches of runs with every effect
                            (diagnosis; later control, design sweeps, uncertainty); per-run parameters,
                            blocked mode, constant / zero-order-hold / linear voltage inputs, per-run
                            sample periods (``simulate_by_period``)
``population``              ``prepare_test``, ``integrate(tests, which, C, m, PopulationSettings) ->
                            BatchResult``: a whole NSGA-II population of (C, m) on T3/T5 of several
                            samples (identification; prescribed exact current, settle detection)
``core``                    the compiled stepping core (numba): RK4 steps of every run through a part of
                            the schedule, contact events, exact sensor lag; its right-hand side, force and
                            contact force are ``fmu_src.effects``' functions as the FMU's integrator
                            compiles them (``fmu_src.integrator.COMPILED_PHYSICS``)
``physics``                 per-run constants and parameter blocks of the core, step-size rules
``mech``, ``settle``        stepping and settle-window truncation of the population runs
``contact``                 event location shared by both (impact, release; numba-callable)
``kernels``                 cached force kernels, stacked tables, fine force tables
``settings``, ``results``   frozen settings (``MechParams``, ``PopulationSettings``, ``Schedule``),
                            ``SimInputError``; ``SimResult``, ``BatchResult``
``fmurun``, ``replay``      the FMU through fmpy; the rig's test protocol replayed on it
==========================  ==========================================================================
"""
