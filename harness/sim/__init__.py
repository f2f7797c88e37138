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
``physics``, ``stepper``    right-hand side from ``fmu_src.effects``; RK4 step, contact events, sensor lag
``mech``, ``settle``        stepping and settle-window truncation of the population runs
``contact``                 event location shared by both (impact, release)
``kernels``                 cached force kernels, stacked tables, fine force tables
``settings``, ``results``   frozen settings (``MechParams``, ``PopulationSettings``, ``Schedule``),
                            ``SimInputError``; ``SimResult``, ``BatchResult``
``fmurun``, ``replay``      the FMU through fmpy; the rig's test protocol replayed on it
==========================  ==========================================================================
"""
